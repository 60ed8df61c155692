#include "cli.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "mirrorcal/sim_host/files.hpp"

namespace mirrorcal::app {

std::string usage() {
  std::string u = "usage: mirrorcal <command> [options]\n";
  for (const auto& c : commands()) u += c.usage;
  return u;
}

void fail(const std::string& msg, int code) {
  // What the command printed so far comes first, also when both streams go to one file (a run
  // that ends on a device error prints its counters, then why it ended).
  std::fflush(stdout);
  std::fprintf(stderr, "mirrorcal: %s\n", msg.c_str());
  std::exit(code);
}

Options parse(int argc, char** argv, int first, const std::vector<std::string>& with_value,
              const std::vector<std::string>& flags, std::size_t max_positional) {
  Options o;
  for (int i = first; i < argc; ++i) {
    const std::string a = argv[i];
    auto in = [&](const std::vector<std::string>& v) {
      for (const auto& s : v)
        if (a == "--" + s) return true;
      return false;
    };
    if (in(with_value)) {
      if (i + 1 >= argc) fail("option " + a + " needs a value\n" + usage());
      o.values[a.substr(2)] = argv[++i];
    } else if (in(flags)) {
      o.values[a.substr(2)] = "1";
    } else if (a.rfind("-", 0) != 0 && o.positional.size() < max_positional) {
      o.positional.push_back(a);
    } else {
      fail("unknown argument '" + a + "'\n" + usage());
    }
  }
  return o;
}

std::uint64_t parse_count(const Options& o, const std::string& key, std::uint64_t def,
                          std::uint64_t min, std::uint64_t max) {
  const std::string s = o.get(key, "");
  if (s.empty()) return def;
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
  if (errno != 0 || end == s.c_str() || *end != '\0' || s[0] == '-' || v < min || v > max)
    fail("--" + key + " must be an integer " +
         (max == UINT64_MAX ? ">= " + std::to_string(min)
                            : "within " + std::to_string(min) + ".." + std::to_string(max)) +
         ", not '" + s + "'");
  return v;
}

sim::Scenario scenario_option(const Options& o, std::uint64_t seed) {
  sim::Scenario s;
  const std::string name = o.get("scenario", "paper");
  if (!sim::scenario_by_name(name, seed, s))
    fail("unknown scenario '" + name + "' (known: paper, random)");
  // --timeshift S: the camera stamps its frames S seconds before the IMU's clock shows them.
  if (o.flag("timeshift")) {
    const std::string text = o.get("timeshift", "");
    char* end = nullptr;
    const double t_d = std::strtod(text.c_str(), &end);
    if (end == text.c_str() || *end != '\0' || !(std::abs(t_d) <= kMaxSimulatedTimeshiftS))
      fail("--timeshift: '" + text + "' is not a time offset in seconds within +-" +
           std::to_string(kMaxSimulatedTimeshiftS).substr(0, 3) + " s");
    s.truth.t_d = t_d;
  }
  // --distortion MODEL: the camera's lens (sim::lens_of: EuRoC cam0's radtan, or a fisheye).
  if (o.flag("distortion")) {
    const std::string name = o.get("distortion", "");
    Distortion d = Distortion::kNone;
    if (!distortion_from_string(name, d))
      fail("--distortion: '" + name + "' is not a lens model (radtan, equidistant or none)");
    sim::set_lens(s, d);
  }
  return s;
}

void create_out_dir(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) fail("cannot create output directory " + dir + ": " + ec.message(), 1);
  std::string error;
  if (!files::lock_folder(dir, error)) fail(error, 1);
}

std::string make_out_dir(const Options& o, const std::string& def) {
  const std::string dir = o.get("out", def);
  create_out_dir(dir);
  return dir;
}

void print_progress(const char* what, double fraction) {
  std::fprintf(stderr, "\r%s %3.0f %%", what, 100.0 * fraction);
  std::fflush(stderr);
}

}  // namespace mirrorcal::app
