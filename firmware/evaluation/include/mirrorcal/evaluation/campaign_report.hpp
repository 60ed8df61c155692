// A Monte Carlo campaign's report (mirrorcal montecarlo), from its runs' outcomes and their
// statistics: the tables it prints (text: the program's stdout), summary.csv, runs.csv and
// batch.csv. A campaign on one rig (the paper's) is set beside the paper's tables; a random
// family's, which has no common truth, by parameter group and by each axis the family draws.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "mirrorcal/evaluation/campaign_statistics.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::evaluation {

// A campaign's files in its folder: summary.csv, runs.csv and with the batch batch.csv, written
// together (io::OutputSet) when all are complete.
class CampaignFiles {
 public:
  // Creates them; false, with a message naming the file, if one cannot be.
  bool open(const std::string& dir, bool batch, std::string& error);
  bool commit(std::string& error) { return set_.commit(error); }
  std::FILE* summary() const { return summary_; }
  std::FILE* runs() const { return runs_; }
  std::FILE* batch() const { return batch_; }  // nullptr without the batch

 private:
  io::OutputSet set_;
  std::FILE *summary_ = nullptr, *runs_ = nullptr, *batch_ = nullptr;
};

// A family's verdict, the average NEES over the rigs against its 99 % interval (and over the runs
// that said consistent: true, when some did not), then report_family's tables.
void report_family_campaign(std::FILE* text, std::FILE* summary,
                            const std::vector<RunOutcome>& runs, const CalibrationLayout& layout,
                            const ErrorStatistics& st);

// A family's statistics of the errors by parameter group (reported_groups(layout): stage 1's
// four, and the camera's and the lens's in stage 2), over all runs and by each axis the family
// draws (family_groups), as a table into text and as rows of summary.csv. Stage 1's columns come
// first, in stage 1's order; stage 2 adds the RMS error and sigma of its groups at the end of
// each row. Only stage 1 has the data's limit. nees99: the 99 % interval of the runs' average.
void report_family(std::FILE* text, std::FILE* summary, const std::vector<RunOutcome>& runs,
                   const CalibrationLayout& layout, const NeesInterval& nees99);

// Tables I-III: each parameter's truth (display units), the paper's final value and sigma, and
// ours over the runs, then the average NEES against its intervals. Tables I and II are stage 1's;
// with the camera's parameters among params, Table III too, estimated after stage 2 or with
// everything in one stage (one_stage).
void print_paper_tables(std::FILE* text, const std::vector<ParamInfo>& params, bool one_stage,
                        const std::vector<double>& truth, const ErrorStatistics& st);

// The runs that took more passes than the default, those a user would have been warned of, and
// those whose ideal-IMU check failed (none: nothing printed).
void print_notable_runs(std::FILE* text, const std::vector<RunOutcome>& runs);

// summary.csv of a campaign on one rig: Tables I-III's columns, then the NEES, how it ran (wall_s
// on `jobs` threads) and with frames the detection.
void write_paper_summary(std::FILE* summary, const std::vector<ParamInfo>& params,
                         const std::vector<double>& truth, const ErrorStatistics& st, double wall_s,
                         std::uint64_t jobs, const FrameMode& frames,
                         const DetectionReport& detection);

// --batch: each group's RMS error of the filter over the batch's on the same runs (a stage 1
// layout), the batch's own NEES and both's time, into text; batch.csv: a row per run solved, of
// the batch's errors and sigmas. A run the batch could not solve is named in text.
void report_batch(std::FILE* text, std::FILE* batch_csv, const std::vector<RunOutcome>& runs,
                  const std::vector<ParamInfo>& params, const CalibrationLayout& layout);

// runs.csv: a row per run, its errors, sigmas, counters, rig and (frames) detection.
void write_runs_csv(std::FILE* runs_csv, const std::vector<RunOutcome>& runs,
                    const std::vector<ParamInfo>& params, bool frames);

// The error plots of every run (plot_errors, titled by the number of runs) in dir, the runs'
// series moved out into them; the PNGs written, or none with the reason in error.
std::vector<std::string> plot_campaign(const std::string& dir, std::vector<RunOutcome>& runs,
                                       const std::vector<ParamInfo>& params,
                                       const ErrorStatistics& st, std::string& error);

}  // namespace mirrorcal::evaluation
