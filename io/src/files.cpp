#include "mirrorcal/io/files.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <utility>

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

namespace mirrorcal::io {

namespace {

std::string reason(int error_number) {
  return std::strerror(error_number != 0 ? error_number : EIO);
}

std::string folder_of(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

// The start of the temporary names of path: hidden, beside it; a writer adds its pid and a count.
std::string temporary_prefix(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  const std::size_t base = slash == std::string::npos ? 0 : slash + 1;
  return path.substr(0, base) + "." + path.substr(base) + ".tmp-";
}

std::string temporary_name(const std::string& path) {
  static std::atomic<unsigned> count{0};
  return temporary_prefix(path) + std::to_string(getpid()) + "-" + std::to_string(count++);
}

// Removes the temporary files of path whose writer is gone (killed before its commit), so that
// they do not pile up.
void remove_orphaned_temporaries(const std::string& path) {
  const std::string prefix = temporary_prefix(path);
  const std::string folder = folder_of(path), name_prefix = prefix.substr(prefix.rfind('/') + 1);
  DIR* d = ::opendir(folder.c_str());
  if (d == nullptr) return;
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name.rfind(name_prefix, 0) != 0) continue;
    const long pid = std::strtol(name.c_str() + name_prefix.size(), nullptr, 10);
    if (pid > 0 && pid != getpid() && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH)
      ::unlink((folder + "/" + name).c_str());
  }
  ::closedir(d);
}

const char* kind_of(mode_t mode) {
  return S_ISFIFO(mode)   ? "a FIFO"
         : S_ISCHR(mode)  ? "a character device"
         : S_ISBLK(mode)  ? "a block device"
         : S_ISDIR(mode)  ? "a folder"
         : S_ISSOCK(mode) ? "a socket"
                          : "another kind of file";
}

// The renames themselves on disk: sync the folder that holds them.
void sync_folder(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

// The signals that end a program and that a user or a service manager sends (Ctrl-C, kill, a
// closed terminal, Ctrl-backslash) wait while a set's files are renamed into place: one that comes
// then is noted, and raised again once the last file is in place, so that it stops the program
// before the first rename or after the last, never between them (SIGKILL still can). Handlers,
// not a blocked mask: a signal sent to the process may be delivered to any of its threads.
class TerminationDeferred {
 public:
  TerminationDeferred() {
    pending_ = 0;
    struct sigaction note {};
    note.sa_handler = [](int signal) { pending_ = signal; };
    sigemptyset(&note.sa_mask);
    for (std::size_t i = 0; i < kSignals.size(); ++i) ::sigaction(kSignals[i], &note, &before_[i]);
  }
  ~TerminationDeferred() {
    for (std::size_t i = 0; i < kSignals.size(); ++i)
      ::sigaction(kSignals[i], &before_[i], nullptr);
    if (pending_ != 0) ::raise(pending_);  // as it would have been handled
  }
  TerminationDeferred(const TerminationDeferred&) = delete;
  TerminationDeferred& operator=(const TerminationDeferred&) = delete;

 private:
  static constexpr std::array<int, 4> kSignals = {SIGINT, SIGTERM, SIGHUP, SIGQUIT};
  static inline volatile std::sig_atomic_t pending_ = 0;
  std::array<struct sigaction, kSignals.size()> before_{};
};

void (*between_renames_for_test)() = nullptr;

}  // namespace

void OutputSet::set_between_renames_for_test(void (*hook)()) {
  between_renames_for_test = hook;
}

struct OutputSet::File {
  std::string path, temporary;
  std::FILE* f = nullptr;
  bool renamed = false;
  ~File() {
    if (f != nullptr) std::fclose(f);
    if (!renamed) ::unlink(temporary.c_str());
  }
  // Everything written on disk, the file closed; false with errno.
  bool flush_and_sync() {
    errno = 0;
    const bool written = std::fflush(f) == 0 && std::ferror(f) == 0;
    const int write_errno = errno;
    const bool synced = written && ::fsync(fileno(f)) == 0;
    const int sync_errno = errno;
    const bool closed = std::fclose(f) == 0;
    f = nullptr;
    errno = !written ? write_errno : !synced ? sync_errno : errno;
    return written && synced && closed;
  }
};

OutputSet::OutputSet() = default;
OutputSet::~OutputSet() = default;

std::FILE* OutputSet::add(const std::string& path, std::string& error) {
  remove_orphaned_temporaries(path);
  auto file = std::make_unique<File>();
  file->path = path;
  file->temporary = temporary_name(path);
  const int fd = ::open(file->temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) {
    discard(path, error);
    return nullptr;
  }
  file->f = ::fdopen(fd, "w");
  if (file->f == nullptr) {
    const int e = errno;
    ::close(fd);
    ::unlink(file->temporary.c_str());
    errno = e;
    discard(path, error);
    return nullptr;
  }
  files_.push_back(std::move(file));
  return files_.back()->f;
}

bool OutputSet::commit(std::string& error) {
  // A file that failed while being written first: the error names it, not a small file whose
  // buffered bytes found the disk full after it.
  std::stable_partition(files_.begin(), files_.end(), [](const std::unique_ptr<File>& file) {
    return std::ferror(file->f) != 0;
  });
  for (auto& file : files_)
    if (!file->flush_and_sync()) return discard(file->path, error);
  const TerminationDeferred deferred;
  for (auto& file : files_) {
    if (::rename(file->temporary.c_str(), file->path.c_str()) != 0)
      return discard(file->path, error);
    file->renamed = true;
    if (between_renames_for_test != nullptr) between_renames_for_test();
  }
  for (auto& file : files_) sync_folder(folder_of(file->path));
  files_.clear();
  return true;
}

bool OutputSet::discard(const std::string& path, std::string& error) {
  error = path + ": cannot write: " + reason(errno);
  files_.clear();  // closes and removes the temporary files
  return false;
}

int open_regular_file(const std::string& path, std::string& error) {
  // O_NONBLOCK: opening a FIFO must not wait for a writer (it changes nothing for a file).
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    error = path + ": cannot open: " + reason(errno);
    return -1;
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    error = path + ": not a regular file (" + kind_of(st.st_mode) + ")";
    return -1;
  }
  return fd;
}

bool read_file(const std::string& path, std::string& text, std::string& error) {
  const int fd = open_regular_file(path, error);
  if (fd < 0) return false;
  struct stat st {};
  ::fstat(fd, &st);
  // Straight into the string, sized from fstat and grown if the file grew: no 64 KiB buffer on
  // the stack.
  text.resize(static_cast<std::size_t>(st.st_size) + 1);
  std::size_t used = 0;
  for (;;) {
    if (used == text.size()) text.resize(2 * text.size());
    const ssize_t n = ::read(fd, text.data() + used, text.size() - used);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      error = path + ": read error: " + reason(errno);
      ::close(fd);
      text.clear();
      return false;
    }
    if (n == 0) break;
    used += static_cast<std::size_t>(n);
  }
  text.resize(used);
  ::close(fd);
  return true;
}

bool write_file(const std::string& path, const std::string& text, std::string& error) {
  OutputSet set;
  std::FILE* f = set.add(path, error);
  if (f == nullptr) return false;
  std::fwrite(text.data(), 1, text.size(), f);
  return set.commit(error);
}

bool lock_folder(const std::string& dir, std::string& error) {
  static std::vector<std::string> held;  // a second lock of ours would refuse us
  if (std::find(held.begin(), held.end(), dir) != held.end()) return true;
  const std::string path = dir + "/" + kLockFile;
  // Never closed: the lock lasts as long as the process, and goes with it however it ends.
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) {
    error = path + ": cannot create the output folder's lock: " + reason(errno);
    return false;
  }
  const bool locked = ::flock(fd, LOCK_EX | LOCK_NB) == 0;
  const int e = errno;
  // A filesystem without locks (NFS without lockd) cannot keep a second writer out; the atomic
  // renames still keep every file whole, so the run goes on.
  if (locked || e == ENOLCK || e == EOPNOTSUPP) {
    held.push_back(dir);
    return true;
  }
  ::close(fd);
  error = e == EWOULDBLOCK ? dir + ": another mirrorcal is writing into this folder (it holds " +
                                 path + "); wait for it to finish or choose another --out"
                           : path + ": cannot lock: " + reason(e);
  return false;
}

// --- StagedFolder ------------------------------------------------------------------------------

namespace {

namespace fs = std::filesystem;

std::string without_slashes(std::string dir) {
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  return dir;
}

// Whether dir holds anything other than a lock file.
bool holds_files(const std::string& dir) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().filename() != kLockFile) return true;
  return false;
}

// Whether the process that wrote a temporary name (its pid follows prefix) is gone.
bool writer_gone(const std::string& name, std::size_t prefix) {
  const long pid = std::strtol(name.c_str() + prefix, nullptr, 10);
  return pid > 0 && pid != getpid() && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

}  // namespace

StagedFolder::~StagedFolder() {
  discard();
}

bool StagedFolder::begin(const std::string& dir, bool replace, std::string& error) {
  dir_ = without_slashes(dir);
  replace_ = replace;
  std::error_code ec;
  if (fs::exists(dir_, ec)) {
    if (!fs::is_directory(dir_, ec)) {
      error = dir_ + ": exists and is not a folder";
      return false;
    }
    if (!lock_folder(dir_, error)) return false;
    if (!replace && holds_files(dir_)) {
      error = dir_ + ": holds a recording already; give --force to replace it (the new one " +
              "replaces it whole, once complete), or choose another --out";
      return false;
    }
  }
  const std::string parent = folder_of(dir_);
  fs::create_directories(parent, ec);
  // The temporary folders of writers killed before (cut recordings this one replaces).
  for (const std::string& cut : cut_folders(dir_)) fs::remove_all(cut, ec);
  temporary_ = temporary_name(dir_);
  if (::mkdir(temporary_.c_str(), 0777) != 0) {
    error = dir_ + ": cannot create its temporary folder " + temporary_ + ": " + reason(errno);
    temporary_.clear();
    return false;
  }
  return lock_folder(temporary_, error);
}

bool StagedFolder::commit(std::string& error) {
  // Every file on disk first: the rename must not publish a folder whose files are still in cache.
  std::error_code ec;
  for (const auto& e : fs::recursive_directory_iterator(temporary_, ec)) {
    const int fd = ::open(e.path().c_str(), O_RDONLY | O_CLOEXEC);
    if (fd >= 0) {
      ::fsync(fd);
      ::close(fd);
    }
  }
  sync_folder(temporary_);
  const bool exists = fs::exists(dir_, ec);
  if (exists && !replace_ && holds_files(dir_)) {
    error = dir_ + ": a recording appeared there while this one was written; give --force to " +
            "replace it";
    discard();
    return false;
  }
  // The old folder and the new swap places in one step; the old is then removed.
  if (exists &&
      ::renameat2(AT_FDCWD, temporary_.c_str(), AT_FDCWD, dir_.c_str(), RENAME_EXCHANGE) != 0) {
    error = dir_ + ": cannot replace it with " + temporary_ + ": " + reason(errno);
    discard();
    return false;
  }
  if (!exists &&
      ::renameat2(AT_FDCWD, temporary_.c_str(), AT_FDCWD, dir_.c_str(), RENAME_NOREPLACE) != 0) {
    error = dir_ + ": cannot rename " + temporary_ + " to it: " + reason(errno);
    discard();
    return false;
  }
  sync_folder(folder_of(dir_));
  if (exists) fs::remove_all(temporary_, ec);  // the old folder, now under the temporary name
  temporary_.clear();
  return true;
}

void StagedFolder::discard() {
  if (temporary_.empty()) return;
  std::error_code ec;
  fs::remove_all(temporary_, ec);
  temporary_.clear();
}

std::string StagedFolder::as_target(std::string message) const {
  if (temporary_.empty()) return message;
  for (std::size_t at; (at = message.find(temporary_)) != std::string::npos;)
    message.replace(at, temporary_.size(), dir_);
  return message;
}

std::vector<std::string> cut_folders(const std::string& dir) {
  const std::string target = without_slashes(dir);
  const std::string prefix = temporary_prefix(target);
  const std::string folder = folder_of(target), name_prefix = prefix.substr(prefix.rfind('/') + 1);
  std::vector<std::string> cut;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(name_prefix, 0) == 0 && e.is_directory(ec) &&
        writer_gone(name, name_prefix.size()))
      cut.push_back(folder + "/" + name);
  }
  std::sort(cut.begin(), cut.end());
  return cut;
}

namespace {
std::atomic<std::size_t> default_buffer_bytes{RecordFile::kDefaultBufferBytes};
}  // namespace

void RecordFile::set_default_buffer_bytes(std::size_t bytes) {
  default_buffer_bytes = bytes > 0 ? bytes : kDefaultBufferBytes;
}

RecordFile::RecordFile(std::size_t record_bytes, std::string label, std::size_t buffer_bytes)
    : record_bytes_(std::max<std::size_t>(record_bytes, 1)),
      capacity_(std::max<std::size_t>(
          (buffer_bytes > 0 ? buffer_bytes : default_buffer_bytes.load()) / record_bytes_, 1)),
      label_(std::move(label)),
      page_(capacity_ * record_bytes_) {
  // Created now, not at the first page's write: the loop that fills it never allocates.
  open();
}

RecordFile::~RecordFile() {
  if (fd_ >= 0) ::close(fd_);
}

RecordFile::RecordFile(RecordFile&& other) noexcept {
  *this = std::move(other);
}

RecordFile& RecordFile::operator=(RecordFile&& other) noexcept {
  if (this == &other) return *this;
  if (fd_ >= 0) ::close(fd_);
  record_bytes_ = other.record_bytes_;
  capacity_ = other.capacity_;
  label_ = std::move(other.label_);
  path_ = std::move(other.path_);
  fd_ = std::exchange(other.fd_, -1);
  size_ = std::exchange(other.size_, 0);
  page_ = std::move(other.page_);
  first_ = other.first_;
  valid_begin_ = other.valid_begin_;
  valid_end_ = other.valid_end_;
  dirty_ = std::exchange(other.dirty_, false);
  other.first_ = other.valid_begin_ = other.valid_end_ = 0;
  return *this;
}

void RecordFile::fail(const char* what, int error_number) const {
  throw StoreError(path_ + ": cannot " + what + " the temporary store of " + label_ + ": " +
                   reason(error_number));
}

void RecordFile::open() const {
  const char* tmp = std::getenv("TMPDIR");
  path_ = std::string(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") + "/mirrorcal-store-XXXXXX";
  fd_ = ::mkostemp(path_.data(), O_CLOEXEC);
  if (fd_ < 0) fail("create", errno);
  ::unlink(path_.c_str());
}

void RecordFile::flush() const {
  if (!dirty_) return;
  const unsigned char* p = page_.data() + (valid_begin_ - first_) * record_bytes_;
  std::size_t left = (valid_end_ - valid_begin_) * record_bytes_;
  auto at = static_cast<off_t>(valid_begin_ * record_bytes_);
  while (left > 0) {
    const ssize_t n = ::pwrite(fd_, p, left, at);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("write", n < 0 ? errno : ENOSPC);
    p += n;
    at += n;
    left -= static_cast<std::size_t>(n);
  }
  dirty_ = false;
}

void RecordFile::place_page(std::size_t k) const {
  flush();
  first_ = k < first_ ? k + 1 - std::min(k + 1, capacity_) : k;
  valid_begin_ = valid_end_ = k;
}

void RecordFile::write(std::size_t k, const void* record) {
  // Into the page if it extends the records current there without a gap.
  const bool in_page = k >= first_ && k < first_ + capacity_;
  const bool adjoins = valid_begin_ == valid_end_ || (k + 1 >= valid_begin_ && k <= valid_end_);
  if (!in_page || !adjoins) place_page(k);
  std::memcpy(page_.data() + (k - first_) * record_bytes_, record, record_bytes_);
  valid_begin_ = std::min(valid_begin_, k);
  valid_end_ = std::max(valid_end_, k + 1);
  dirty_ = true;
  size_ = std::max(size_, k + 1);
}

void RecordFile::read(std::size_t k, void* record) const {
  if (k >= size_) throw std::out_of_range("RecordFile::read beyond its records");
  if (k < valid_begin_ || k >= valid_end_) {
    place_page(k);
    const std::size_t count = std::min(capacity_, size_ - first_);
    unsigned char* p = page_.data();
    std::size_t left = count * record_bytes_;
    auto at = static_cast<off_t>(first_ * record_bytes_);
    while (left > 0) {
      const ssize_t n = ::pread(fd_, p, left, at);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) fail("read", errno);
      if (n == 0) {  // a hole at the end, never written: zeros
        std::memset(p, 0, left);
        break;
      }
      p += n;
      at += n;
      left -= static_cast<std::size_t>(n);
    }
    valid_begin_ = first_;
    valid_end_ = first_ + count;
  }
  std::memcpy(record, page_.data() + (k - first_) * record_bytes_, record_bytes_);
}

bool is_staging_folder(const std::string& dir) {
  const std::string target = without_slashes(dir);
  const std::string name = target.substr(target.rfind('/') + 1);
  return name.size() > 1 && name[0] == '.' && name.find(".tmp-") != std::string::npos;
}

}  // namespace mirrorcal::io
