// Files read and written safely. Only regular files are read: a FIFO or a device (/dev/zero) is
// refused, never waited on or read without end.
//
// Results are written whole or not at all. Every file mirrorcal writes goes first to a temporary
// file beside it (same folder, so the rename is atomic), is flushed and synced to disk, and is
// renamed over its name only when all of its set is complete: a full disk, a crash or a kill leaves
// the earlier results as they were, never a cut file. A lock on the output folder keeps a second
// mirrorcal from writing into it at the same time.
#pragma once

#include <cstddef>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace mirrorcal::io {

// The files of one result, committed together.
class OutputSet {
 public:
  OutputSet();
  ~OutputSet();  // removes the temporary files of a set never committed
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;

  // A new temporary file for path, open for writing; nullptr with a message naming path if it
  // cannot be created.
  std::FILE* add(const std::string& path, std::string& error);
  // Flushes and syncs every file, then renames each over its path; if any cannot be written
  // (a full disk), none is renamed and error names that file. A set that failed is discarded.
  // SIGINT, SIGTERM, SIGHUP and SIGQUIT wait until the renames are done, so that a signal does
  // not leave some of each set. A rename that fails part-way (or SIGKILL, or a power cut, between
  // two renames) does leave a mix: each file whole, the earlier ones new. One thread at a time:
  // the deferral swaps the process's handlers.
  bool commit(std::string& error);
  // For tests: hook is called after each file is renamed into place (nullptr: none).
  static void set_between_renames_for_test(void (*hook)());

 private:
  struct File;
  // Sets error for path from errno, removes every temporary file and returns false.
  bool discard(const std::string& path, std::string& error);
  std::vector<std::unique_ptr<File>> files_;
};

// The regular file path opened for reading (a descriptor the caller closes); -1 with read_file's
// message otherwise.
int open_regular_file(const std::string& path, std::string& error);

// The whole of the regular file path into text; false with a message naming path otherwise
// ("PATH: cannot open: reason", "PATH: not a regular file").
bool read_file(const std::string& path, std::string& text, std::string& error);

// text as the whole of path, through an OutputSet of one.
bool write_file(const std::string& path, const std::string& text, std::string& error);

// The lock file in an output folder: a mirrorcal writing into the folder holds an exclusive
// flock() on it for as long as it runs.
constexpr const char* kLockFile = ".mirrorcal.lock";
// Takes that lock on dir for the rest of the process; false, with a message naming the folder,
// if another process holds it.
bool lock_folder(const std::string& dir, std::string& error);

// A folder written whole or not at all (a recording): its files go into a fresh hidden folder
// beside it (.NAME.tmp-PID-N), which replaces the folder only when complete. A kill leaves that
// temporary folder (cut_folders() finds it) and the folder as it was.
class StagedFolder {
 public:
  StagedFolder() = default;
  ~StagedFolder();  // removes the temporary folder if never committed
  StagedFolder(const StagedFolder&) = delete;
  StagedFolder& operator=(const StagedFolder&) = delete;

  // Creates the temporary folder for dir. Refused (false, with a message naming dir) if dir holds
  // anything but a lock file and replace is false, or another mirrorcal writes into it.
  bool begin(const std::string& dir, bool replace, std::string& error);
  // Where the files go until commit().
  const std::string& path() const { return temporary_; }
  // Syncs the temporary folder and renames it over dir; false with a message if it cannot (or,
  // without replace, if a folder with files appeared at dir meanwhile).
  bool commit(std::string& error);
  // Removes the temporary folder.
  void discard();
  // message with the temporary folder's path given as dir's: what the user asked to write.
  std::string as_target(std::string message) const;

 private:
  std::string dir_, temporary_;
  bool replace_ = false;
};

// The temporary folders beside dir of StagedFolders whose writer was killed before committing.
std::vector<std::string> cut_folders(const std::string& dir);
// Whether dir is such a temporary folder (by its name).
bool is_staging_folder(const std::string& dir);

// A temporary store that could not be created, written or read (a full disk): its message names
// the store's file and the reason. The commands exit with it (code 1), as with a result they could
// not write.
class StoreError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Fixed-size records numbered from 0 in a temporary file, so that what a calibration keeps per
// frame takes disk, not memory: the file is created in $TMPDIR (/tmp without it) and unlinked at
// once (nothing is left behind, whatever ends the process), and only one page of records
// (buffer_bytes, at least one record) is held in memory. Records are written anywhere (holes read
// as zeros), in order or in reverse, and read in either order at the cost of one pread per page.
// Any failure (a full disk) throws StoreError naming the file.
class RecordFile {
 public:
  static constexpr std::size_t kDefaultBufferBytes = 64 * 1024;
  // label says whose store it is in messages ("the calibration's frames"); buffer_bytes 0: the
  // default (kDefaultBufferBytes, or set_default_buffer_bytes's).
  RecordFile(std::size_t record_bytes, std::string label, std::size_t buffer_bytes = 0);
  // The page of the stores created after it, for tests: one that holds a whole store keeps it in
  // memory and never touches the file, the reference the file is compared with.
  static void set_default_buffer_bytes(std::size_t bytes);
  ~RecordFile();
  RecordFile(RecordFile&& other) noexcept;
  RecordFile& operator=(RecordFile&& other) noexcept;
  RecordFile(const RecordFile&) = delete;
  RecordFile& operator=(const RecordFile&) = delete;

  // Record k from record_bytes bytes at record; size() grows to k + 1 if it was smaller.
  void write(std::size_t k, const void* record);
  void append(const void* record) { write(size_, record); }
  // Record k (< size()) into record.
  void read(std::size_t k, void* record) const;
  std::size_t size() const { return size_; }
  std::size_t record_bytes() const { return record_bytes_; }
  // Where the file was created (it has no name left once open).
  const std::string& path() const { return path_; }

 private:
  void open() const;
  // Writes the page's records written since it was last written; throws StoreError.
  void flush() const;
  [[noreturn]] void fail(const char* what, int error_number) const;
  // Moves the page so that it holds k, going forwards from k or, if k lies before the page,
  // backwards so that k is its last record.
  void place_page(std::size_t k) const;

  std::size_t record_bytes_ = 0, capacity_ = 0;  // capacity_: records in the page
  std::string label_;
  mutable std::string path_;
  mutable int fd_ = -1;
  std::size_t size_ = 0;
  mutable std::vector<unsigned char> page_;
  // The page holds records [first_, first_ + capacity_); those in [valid_begin_, valid_end_) are
  // current, and written to the file only when dirty_.
  mutable std::size_t first_ = 0, valid_begin_ = 0, valid_end_ = 0;
  mutable bool dirty_ = false;
};

}  // namespace mirrorcal::io
