#include "mirrorcal/drivers/driver_error.hpp"

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>

namespace mirrorcal::drivers {

const char* fault_name(Fault fault) {
  switch (fault) {
    case Fault::kMissing:
      return "missing";
    case Fault::kBusy:
      return "busy";
    case Fault::kWrongKind:
      return "wrong kind of device";
    case Fault::kNotAnswering:
      return "not answering";
    case Fault::kBadSpec:
      return "bad device specification";
    case Fault::kIo:
      return "I/O error";
  }
  return "?";
}

Fault fault_from_errno(int err) {
  switch (err) {
    case ENOENT:
    case ENODEV:
    case ENXIO:
      return Fault::kMissing;
    case EBUSY:
    case EAGAIN:
      return Fault::kBusy;
    case ENOTTY:
    case EINVAL:
    case EOPNOTSUPP:
    case EAFNOSUPPORT:
    case EPROTONOSUPPORT:
      return Fault::kWrongKind;
    case ETIMEDOUT:
    case EREMOTEIO:
    case EIO:
    case ENETDOWN:
    case ESHUTDOWN:
      return Fault::kNotAnswering;
    default:
      return Fault::kIo;
  }
}

DriverError os_error(const std::string& device, const std::string& what, int err) {
  const Fault fault = fault_from_errno(err);
  return DriverError(
      fault, device + ": " + what + ": " + std::strerror(err) + " (" + fault_name(fault) + ")");
}

void ErrorText::set(const char* format, ...) {
  va_list args;
  va_start(args, format);
  std::vsnprintf(text_, sizeof(text_), format, args);
  va_end(args);
}

}  // namespace mirrorcal::drivers
