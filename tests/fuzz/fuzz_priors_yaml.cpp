// libFuzzer target: mirrorcal.yaml, the priors beside a recording. Any input gives priors or a
// message naming the file, never a crash; accepted priors are finite, with positive sigmas.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "mirrorcal/io/recording.hpp"

namespace {

bool positive(const Eigen::Vector3d& sigma) {
  return sigma.allFinite() && sigma.minCoeff() > 0;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace io = mirrorcal::io;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  std::string error;
  std::vector<std::string> notes;
  io::RecordingPriors p;
  const bool ok =
      io::parse_priors_yaml(text, "mirrorcal.yaml", {800, 800, 320, 240, 0}, p, notes, error);
  if (ok != error.empty()) std::abort();
  if (!ok) {
    if (error.rfind("mirrorcal.yaml", 0) != 0) std::abort();  // the message names the file
    return 0;
  }
  if (!positive(p.sigma_p_n_b) || !positive(p.sigma_v_n_b) || !positive(p.sigma_rot_n_b) ||
      !positive(p.sigma_b_a) || !positive(p.sigma_b_g) || !positive(p.sigma_p_b_c) ||
      !positive(p.sigma_rot_b_c) || !(p.pixel_sigma > 0) || !(p.sigma_t_d > 0))
    std::abort();
  if (!p.gravity_n.allFinite() || !p.p_n_b.allFinite() || !p.p_b_c.allFinite() ||
      !p.q_n_b.coeffs().allFinite() || !p.q_b_c.coeffs().allFinite() || !std::isfinite(p.t_d))
    std::abort();
  if (p.features_c.size() != p.sigma_features_c.size()) std::abort();
  for (std::size_t i = 0; i < p.features_c.size(); ++i)
    if (!p.features_c[i].allFinite() || !positive(p.sigma_features_c[i])) std::abort();
  // The filter's prior follows for exactly M = 3 markers.
  mirrorcal::Prior<3> prior;
  if (io::to_prior(p, prior, error) != (p.features_c.size() == 3)) std::abort();
  return 0;
}
