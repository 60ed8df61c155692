#include "mirrorcal/evaluation/batch_outcome.hpp"

#include "mirrorcal/estimator/marker_counts.hpp"
#include "mirrorcal/evaluation/batch.hpp"

namespace mirrorcal::evaluation {

namespace {

template <int M>
BatchOutcome solve(const sim::Scenario& rig, std::uint64_t seed, ImuModel imu_model) {
  BatchOutcome out;
  const sim::SimData data = sim::simulate(rig, seed);
  const io::RecordingPriors priors = io::from_prior(sim::simulation_prior<M>(rig, data, seed),
                                                    rig.gravity_n, rig.pixel_sigma, false);
  calibration::CalibrationResult r;
  BatchReport report;
  if (!solve_batch(simulated_batch_input(rig, data, priors, 0, imu_model), {}, r, report,
                   out.failure))
    return out;
  const TruthError t = truth_error(r, sim::recording_truth(rig));
  out.error = t.error;
  out.nees = t.nees;
  for (std::size_t j = 0; j < r.params.size(); ++j)
    out.sigma.push_back(r.sigma[j] * r.params[j].scale);
  out.cpu_s = report.cpu_s;
  out.converged = report.converged;
  return out;
}

}  // namespace

BatchOutcome solve_batch_outcome(const sim::Scenario& rig, std::uint64_t seed, ImuModel imu_model) {
  BatchOutcome out;
  out.failure =
      "this build has no filter of " + std::to_string(rig.truth.markers.size()) + " markers";
  with_marker_count(static_cast<int>(rig.truth.markers.size()), [&](auto markers) {
    out = solve<decltype(markers)::value>(rig, seed, imu_model);
  });
  return out;
}

}  // namespace mirrorcal::evaluation
