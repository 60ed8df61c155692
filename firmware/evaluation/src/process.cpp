#include "mirrorcal/evaluation/process.hpp"

#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

extern char** environ;

namespace mirrorcal::evaluation {

namespace {

// The child's standard streams and folder, set up by posix_spawn between fork and exec.
class SpawnActions {
 public:
  SpawnActions(const std::string& cwd, const std::string& output_path) {
    posix_spawn_file_actions_init(&actions_);
    posix_spawn_file_actions_addopen(&actions_, 0, "/dev/null", O_RDONLY, 0);
    if (!output_path.empty()) {  // opened before the chdir: a relative path is ours
      posix_spawn_file_actions_addopen(&actions_, 1, output_path.c_str(),
                                       O_WRONLY | O_CREAT | O_TRUNC, 0644);
      posix_spawn_file_actions_adddup2(&actions_, 1, 2);
    }
    if (!cwd.empty()) posix_spawn_file_actions_addchdir_np(&actions_, cwd.c_str());
  }
  ~SpawnActions() { posix_spawn_file_actions_destroy(&actions_); }
  SpawnActions(const SpawnActions&) = delete;
  SpawnActions& operator=(const SpawnActions&) = delete;
  const posix_spawn_file_actions_t* get() const { return &actions_; }

 private:
  posix_spawn_file_actions_t actions_;
};

}  // namespace

ProgramExit run_program(const std::vector<std::string>& argv, const std::string& cwd,
                        const std::string& output_path) {
  ProgramExit exit;
  if (argv.empty()) {
    exit.error = "no program to run";
    return exit;
  }
  const std::string& name = argv[0];
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const SpawnActions actions(cwd, output_path);
  pid_t pid = 0;
  // glibc's posix_spawnp reports a program that could not be executed here, not as exit 127.
  if (const int e = posix_spawnp(&pid, name.c_str(), actions.get(), nullptr, args.data(), environ);
      e != 0) {
    exit.error = "cannot run " + name + ": " + std::strerror(e);
    return exit;
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) {
      exit.error = "cannot wait for " + name + ": " + std::strerror(errno);
      return exit;
    }
  if (WIFSIGNALED(status)) {
    exit.status = 128 + WTERMSIG(status);
    exit.error = name + " was killed by signal " + std::to_string(WTERMSIG(status));
  } else {
    exit.status = WEXITSTATUS(status);
    if (exit.status != 0)
      exit.error = name + " failed (exit status " + std::to_string(exit.status) + ")";
  }
  return exit;
}

}  // namespace mirrorcal::evaluation
