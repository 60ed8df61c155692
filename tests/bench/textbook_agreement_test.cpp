// The textbook full-state UKF the benchmark measures the filter against computes the same thing
// on the bench's inputs (a filter near convergence, where the two transforms agree to second
// order in the spread): otherwise the benchmark's ratio would compare different work.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "filter_ops.hpp"

namespace mb = mirrorcal::bench;

namespace {

// The two estimates (error-state offsets from the start, then covariance entries) agree, each part
// to a fraction of its largest entry in the filter's.
void expect_agree(const std::vector<double>& filter, const std::vector<double>& textbook, int dim,
                  const char* what) {
  ASSERT_EQ(filter.size(), textbook.size());
  for (const bool covariance : {false, true}) {
    const std::size_t begin = covariance ? std::size_t(dim) : 0;
    const std::size_t end = covariance ? filter.size() : std::size_t(dim);
    double scale = 0.0, worst = 0.0;
    for (std::size_t i = begin; i < end; ++i) {
      scale = std::max(scale, std::abs(filter[i]));
      worst = std::max(worst, std::abs(filter[i] - textbook[i]));
    }
    std::printf("%s, %s: largest difference %.3g of %.3g\n", what,
                covariance ? "covariance" : "estimate", worst, scale);
    EXPECT_GT(scale, 0.0) << what;
    // Near convergence (sigmas of 1e-4) the two transforms differ at second order in the spread:
    // 3e-6 of the update's step, 1e-8 of the predict's, 1e-9 of the covariances.
    EXPECT_LT(worst, (covariance ? 1e-8 : 1e-5) * scale)
        << what << (covariance ? ", covariance" : ", estimate");
  }
}

TEST(TextbookUkf, AgreesWithTheFilterOnTheBenchInputs) {
  for (const int m : mb::built_marker_counts()) {
    const auto filter = mb::make_filter_ops(m, false);
    const auto textbook = mb::make_textbook_ops(m);
    if (textbook == nullptr) continue;
    SCOPED_TRACE(m);
    filter->restore();
    textbook->restore();
    ASSERT_TRUE(filter->predict());
    ASSERT_TRUE(textbook->predict());
    expect_agree(filter->estimate(), textbook->estimate(), filter->dim(), "predict");
    filter->restore();
    textbook->restore();
    ASSERT_TRUE(filter->update());
    ASSERT_TRUE(textbook->update());
    expect_agree(filter->estimate(), textbook->estimate(), filter->dim(), "update");
  }
}

}  // namespace
