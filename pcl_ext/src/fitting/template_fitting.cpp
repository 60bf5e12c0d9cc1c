// Explicit instantiations of tbsp::TemplateFitting for the point types tbsp supports out of the box.
#include <pcl/point_types.h>

#include "tbsp/fitting/impl/template_fitting.hpp"

TBSP_INSTANTIATE_TemplateFitting(pcl::PointXYZ)
TBSP_INSTANTIATE_TemplateFitting(pcl::PointNormal)
TBSP_INSTANTIATE_TemplateFitting(pcl::PointXYZRGBNormal)
