// The built-in stage plugin (libtbsp_stages.so): readers, PCL filters, template fitting,
// Laplacian deformation, writers.
// Loaded from the plugin path like any third-party plugin (docs/plugins.md).
#include "stage_util.h"

TBSP_STAGE_PLUGIN(registry) {
  tbsp::pipeline::builtin::register_io_stages(registry);
  tbsp::pipeline::builtin::register_pcl_stages(registry);
  tbsp::pipeline::builtin::register_fit_stages(registry);
  tbsp::pipeline::builtin::register_deform_stages(registry);
  tbsp::pipeline::builtin::register_mesh_stages(registry);
  tbsp::pipeline::builtin::register_texture_stages(registry);
}
