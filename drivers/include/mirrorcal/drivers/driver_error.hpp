// What went wrong with a device, in words a user can act on. Opening a device throws DriverError;
// once streaming, sources report failures through hal's kError and error() instead, with the
// message kept in a fixed buffer (no allocation on the hot path).
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

namespace mirrorcal::drivers {

enum class Fault {
  kMissing,       // no such device, interface or line
  kBusy,          // another user (a kernel driver or a process) holds it
  kWrongKind,     // it exists but is not the expected kind of device or part
  kNotAnswering,  // it was there but does not (or no longer) answer
  kBadSpec,       // the device specification itself is malformed
  kIo,            // any other failure of the operating system
};

const char* fault_name(Fault fault);

class DriverError : public std::runtime_error {
 public:
  DriverError(Fault fault, const std::string& message)
      : std::runtime_error(message), fault_(fault) {}
  Fault fault() const { return fault_; }

 private:
  Fault fault_;
};

// The fault an errno value of a failed open or ioctl means.
Fault fault_from_errno(int err);

// "DEVICE: WHAT: strerror (FAULT)" as a DriverError, the fault chosen from err.
DriverError os_error(const std::string& device, const std::string& what, int err);

// A message of at most 191 characters, formatted without allocating (for error() of sources).
class ErrorText {
 public:
  void set(const char* format, ...) __attribute__((format(printf, 2, 3)));
  void clear() { text_[0] = '\0'; }
  const char* c_str() const { return text_; }
  bool empty() const { return text_[0] == '\0'; }

 private:
  char text_[192] = {};
};

}  // namespace mirrorcal::drivers
