#include "mirrorcal/drivers/gpio_lines.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>
#include <string>

namespace mirrorcal::drivers {
namespace {

// Opens the chip and finds the line, free for us to request; throws otherwise.
gpiod_line* find_line(const LineSpec& spec, gpiod_chip*& chip) {
  chip = gpiod_chip_open_lookup(spec.chip.c_str());
  if (chip == nullptr) {
    const int err = errno;
    if (err == ENOENT || err == ENODEV)
      throw DriverError(Fault::kMissing, spec.text + ": no GPIO chip '" + spec.chip + "'");
    if (err == ENOTTY || err == EINVAL)
      throw DriverError(Fault::kWrongKind, spec.text + ": '" + spec.chip + "' is not a GPIO chip");
    throw os_error(spec.text, "cannot open GPIO chip '" + spec.chip + "'", err);
  }
  const unsigned lines = gpiod_chip_num_lines(chip);
  if (spec.line >= lines) {
    gpiod_chip_close(chip);
    chip = nullptr;
    throw DriverError(Fault::kMissing, spec.text + ": " + spec.chip + " has " +
                                           std::to_string(lines) + " lines, no line " +
                                           std::to_string(spec.line));
  }
  gpiod_line* line = gpiod_chip_get_line(chip, spec.line);
  if (line == nullptr) {
    const int err = errno;
    gpiod_chip_close(chip);
    chip = nullptr;
    throw os_error(spec.text, "cannot get the line", err);
  }
  return line;
}

[[noreturn]] void request_failed(const LineSpec& spec, gpiod_chip*& chip, gpiod_line* line,
                                 int err) {
  std::string holder;
  if (err == EBUSY) {
    gpiod_line_update(line);
    const char* c = gpiod_line_consumer(line);
    holder = c != nullptr ? std::string(" by '") + c + "'" : std::string(" by another user");
  }
  gpiod_chip_close(chip);
  chip = nullptr;
  if (err == EBUSY)
    throw DriverError(Fault::kBusy, spec.text + ": the line is in use" + holder + " (busy)");
  throw os_error(spec.text, "cannot request the line", err);
}

}  // namespace

GpioDataReady::GpioDataReady(const LineSpec& spec, const char* consumer) : spec_(spec) {
  line_ = find_line(spec, chip_);
  if (gpiod_line_request_rising_edge_events(line_, consumer) != 0)
    request_failed(spec, chip_, line_, errno);
}

GpioDataReady::~GpioDataReady() {
  if (chip_ != nullptr) gpiod_chip_close(chip_);  // releases the line too
}

hal::SourceStatus GpioDataReady::wait_rising(std::int64_t timeout_ns, std::int64_t& t_ns) {
  timespec timeout{};
  timeout.tv_sec = static_cast<time_t>(timeout_ns / 1'000'000'000);
  timeout.tv_nsec = static_cast<long>(timeout_ns % 1'000'000'000);
  bool have_edge = false;
  for (;;) {
    const int ready = gpiod_line_event_wait(line_, &timeout);
    if (ready == 0) return have_edge ? hal::SourceStatus::kOk : hal::SourceStatus::kNotReady;
    if (ready < 0) {
      if (errno == EINTR) continue;
      error_.set("%s: waiting for an edge failed: %s", spec_.text.c_str(), std::strerror(errno));
      return hal::SourceStatus::kError;
    }
    // Everything queued since the last call, in one read: the part's data registers hold only
    // the newest sample, so the newest rising edge is the one that times it. Older edges are
    // samples nobody read; their times are skipped, and the caller sees the gap as missed samples.
    gpiod_line_event events[16];
    const int n = gpiod_line_event_read_multiple(line_, events, 16);
    if (n < 0) {
      error_.set("%s: reading an edge failed: %s", spec_.text.c_str(), std::strerror(errno));
      return hal::SourceStatus::kError;
    }
    for (int i = 0; i < n; ++i) {
      if (events[i].event_type != GPIOD_LINE_EVENT_RISING_EDGE) continue;
      ++edges_;
      t_ns = static_cast<std::int64_t>(events[i].ts.tv_sec) * 1'000'000'000 + events[i].ts.tv_nsec;
      have_edge = true;
    }
    if (have_edge && n < 16) return hal::SourceStatus::kOk;
    // A full read may have left edges in the queue: look again, without waiting once an edge is
    // in hand.
    if (have_edge) timeout = timespec{};
  }
}

GpioOutput::GpioOutput(const LineSpec& spec, bool active_low, const char* consumer,
                       bool initially_active)
    : spec_(spec) {
  line_ = find_line(spec, chip_);
  const int flags = active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (gpiod_line_request_output_flags(line_, consumer, flags, initially_active ? 1 : 0) != 0)
    request_failed(spec, chip_, line_, errno);
}

GpioOutput::~GpioOutput() {
  if (chip_ != nullptr) gpiod_chip_close(chip_);
}

bool GpioOutput::set(bool active) {
  if (gpiod_line_set_value(line_, active ? 1 : 0) == 0) return true;
  error_.set("%s: setting the line failed: %s", spec_.text.c_str(), std::strerror(errno));
  return false;
}

bool GpioOutput::get() {
  const int v = gpiod_line_get_value(line_);
  if (v < 0)
    error_.set("%s: reading the line failed: %s", spec_.text.c_str(), std::strerror(errno));
  return v == 1;
}

}  // namespace mirrorcal::drivers
