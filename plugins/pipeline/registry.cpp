// Registry::load*: finds and opens stage plugins (dlopen), checks their ABI version and lets them
// register their stages (stage.h).
#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "tbsp/core/logging.h"
#include "tbsp/plugins/stage.h"

namespace fs = std::filesystem;

namespace tbsp::pipeline {

void Registry::load(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw FileError("plugin '" + path + "': no such file");
  const std::string name = fs::path(path).filename().string();
  if (std::find(loaded_names_.begin(), loaded_names_.end(), name) != loaded_names_.end()) {
    logger()->debug("plugin {}: a library named {} is already loaded; skipped", path, name);
    return;
  }
  // RTLD_LOCAL: a plugin's own copies of libraries it linked statically stay private to it;
  // RTLD_NODELETE: the library stays mapped until exit (stage objects and the exceptions they
  // throw may outlive the registry).
  void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL | RTLD_NODELETE);
  if (!h) {
    const char* e = dlerror();
    throw FileError("plugin '" + path + "' cannot be loaded: " + (e ? e : "unknown error") +
                    " (a missing library it depends on is named here; rebuild the plugin against this tbsp)");
  }
  using AbiFn = int (*)();
  using RegisterFn = void (*)(Registry&);
  auto abi = reinterpret_cast<AbiFn>(dlsym(h, "tbsp_plugin_abi_version"));
  auto reg = reinterpret_cast<RegisterFn>(dlsym(h, "tbsp_register_stages"));
  if (!abi || !reg) {
    dlclose(h);
    throw InvalidInput("'" + path + "' is not a tbsp stage plugin (no TBSP_STAGE_PLUGIN entry point; see docs/plugins.md)");
  }
  if (abi() != kPluginAbiVersion) {
    const int v = abi();
    dlclose(h);
    throw InvalidInput("plugin '" + path + "' was built for tbsp plugin ABI " + std::to_string(v) + ", this tbsp has ABI " +
                       std::to_string(kPluginAbiVersion) + ": rebuild the plugin against the installed tbsp");
  }
  loaded_names_.push_back(name);
  libraries_.push_back(std::shared_ptr<void>(h, [](void*) {}));  // never closed (RTLD_NODELETE)
  const std::string before = current_plugin_;
  current_plugin_ = name;
  try {
    reg(*this);
  } catch (...) {
    current_plugin_ = before;
    throw;
  }
  current_plugin_ = before;
}

int Registry::load_folder(const std::string& folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return 0;
  std::vector<fs::path> libs;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.is_regular_file(ec) && e.path().extension() == ".so") libs.push_back(e.path());
  std::sort(libs.begin(), libs.end());  // deterministic order
  int n = 0;
  for (const auto& l : libs) {
    const std::size_t before = loaded_names_.size();
    load(l.string());
    n += loaded_names_.size() > before;
  }
  return n;
}

std::vector<std::string> Registry::default_path() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("TBSP_PLUGIN_PATH")) {
    std::string s = env;
    std::size_t a = 0;
    while (a <= s.size()) {
      const std::size_t b = std::min(s.find(':', a), s.size());
      if (b > a) dirs.push_back(s.substr(a, b - a));
      a = b + 1;
    }
  }
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) dirs.push_back((exe.parent_path().parent_path() / "lib" / "tbsp" / "plugins").string());
#ifdef TBSP_INSTALL_PLUGIN_DIR
  dirs.push_back(TBSP_INSTALL_PLUGIN_DIR);
#endif
#ifdef TBSP_BUILD_PLUGIN_DIR
  dirs.push_back(TBSP_BUILD_PLUGIN_DIR);
#endif
  return dirs;
}

void Registry::load_default_path() {
  for (const auto& d : default_path()) load_folder(d);
}

}  // namespace tbsp::pipeline
