#pragma once
// Errors that say where they come from. Scene problems carry file:line so a user can fix
// the file; simulation failures carry the time, step and particle.
#include <stdexcept>
#include <string>
#include <vector>

namespace m3dp {

/// A place in a user's input file. line is 1-based; 0 means "whole file".
struct SourceLocation {
  std::string file;
  int line = 0;
  [[nodiscard]] std::string str() const;
};

/// One problem found in an input: where it is and what was expected.
struct Diagnostic {
  SourceLocation location;
  std::string message;
  [[nodiscard]] std::string str() const;  // "file:line: error: message"
};

/// Base class of every M3DP error.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// An input file (scene, mesh, toolpath) is wrong; holds every problem found, not just the first.
class InputError : public Error {
 public:
  explicit InputError(std::vector<Diagnostic> diagnostics);
  InputError(SourceLocation location, const std::string& message);
  [[nodiscard]] const std::vector<Diagnostic>& diagnostics() const { return diagnostics_; }

 private:
  std::vector<Diagnostic> diagnostics_;
};

/// The simulation reached a state it cannot continue from (NaN, explosion).
class SimulationError : public Error {
 public:
  using Error::Error;
};

}  // namespace m3dp
