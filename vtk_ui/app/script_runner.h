#pragma once
/// \file script_runner.h
/// \brief `tbsp-studio --script actions.json`: replays interactions on the real window, one
/// action after the other, with the Qt event loop running between them (so the solver thread,
/// the view updates and the responsiveness measurement behave as with a person at the mouse).
/// Format and actions: docs/studio.md. An action that fails prints its message (naming the
/// action's index) and the script goes on — as a user would after an error dialog; the exit
/// code is then 2.

#include <QObject>
#include <QTimer>
#include <nlohmann/json.hpp>
#include <string>

namespace tbsp::studio {

class StudioWindow;

class ScriptRunner : public QObject {
  Q_OBJECT
public:
  /// \throws FileError naming the file and the action when the script is malformed (checked
  /// before anything runs).
  ScriptRunner(StudioWindow& w, const std::string& path);
  void start();

private slots:
  void step();

private:
  bool run(const nlohmann::json& a);  // false: wait (poll again)
  void next();
  void writeReport(const std::string& path);

  StudioWindow& w_;
  std::string path_;
  nlohmann::json actions_;
  std::size_t index_ = 0;
  bool waiting_ = false;
  QTimer poll_;
};

/// Checks a script's structure (known actions, argument types). \throws FileError
/// "FILE: actions[3] (\"drag\"): ...".
nlohmann::json load_script(const std::string& path);

}  // namespace tbsp::studio
