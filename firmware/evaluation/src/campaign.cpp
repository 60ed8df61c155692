#include "mirrorcal/evaluation/campaign.hpp"

#include <atomic>
#include <mutex>
#include <thread>

#include "mirrorcal/io/files.hpp"

namespace mirrorcal::evaluation {

bool run_campaign(std::vector<RunOutcome>& out, std::uint64_t jobs,
                  const std::function<void(std::uint64_t, RunOutcome&)>& run,
                  const std::function<void(double)>& progress, std::string& store_error) {
  const std::uint64_t runs = out.size();
  std::atomic<std::uint64_t> next{0}, done{0};
  std::mutex mu;
  auto worker = [&] {
    for (std::uint64_t i; (i = next++) < runs;) {
      try {
        run(i, out[i]);
      } catch (const io::StoreError& e) {  // a full $TMPDIR: no more runs, the caller says why
        std::lock_guard<std::mutex> lock(mu);
        if (store_error.empty()) store_error = e.what();
        next = runs;
        return;
      }
      std::lock_guard<std::mutex> lock(mu);
      progress(double(++done) / double(runs));
    }
  };
  std::vector<std::thread> pool;
  for (std::uint64_t j = 0; j < jobs; ++j) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  return store_error.empty();
}

}  // namespace mirrorcal::evaluation
