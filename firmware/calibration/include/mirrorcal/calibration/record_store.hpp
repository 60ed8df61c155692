// What a calibration keeps per frame (its history rows, the tracking pass's motion steps, the
// smoothed trajectory), held in a temporary file rather than in memory: memory stays bounded
// whatever the recording's length (io::RecordFile, a page of records in memory). Read like a
// std::vector, but each element by value.
#pragma once

#include <cstddef>
#include <iterator>
#include <string>
#include <type_traits>
#include <utility>

#include "mirrorcal/io/files.hpp"

namespace mirrorcal::calibration {

template <class T>
class RecordStore {
  // Records are copied as their bytes: T must own nothing outside itself (fixed-size Eigen types,
  // arrays and scalars, no std::vector or std::string).
  static_assert(std::is_trivially_destructible_v<T>, "a record is copied as its bytes");

 public:
  RecordStore() : RecordStore("the calibration's frames") {}
  explicit RecordStore(std::string label) : file_(sizeof(T), std::move(label)) {}

  void push_back(const T& record) { file_.append(&record); }
  // Record k (size() grows to k + 1 if it was smaller).
  void set(std::size_t k, const T& record) { file_.write(k, &record); }
  T operator[](std::size_t k) const {
    T record;
    file_.read(k, static_cast<void*>(&record));
    return record;
  }
  T front() const { return (*this)[0]; }
  T back() const { return (*this)[size() - 1]; }
  std::size_t size() const { return file_.size(); }
  bool empty() const { return size() == 0; }

  class const_iterator {
   public:
    using iterator_category = std::input_iterator_tag;
    using value_type = T;
    using difference_type = std::ptrdiff_t;
    using pointer = void;
    using reference = T;
    const_iterator(const RecordStore* store, std::size_t k) : store_(store), k_(k) {}
    T operator*() const { return (*store_)[k_]; }
    const_iterator& operator++() {
      ++k_;
      return *this;
    }
    bool operator==(const const_iterator& o) const { return k_ == o.k_; }
    bool operator!=(const const_iterator& o) const { return k_ != o.k_; }

   private:
    const RecordStore* store_;
    std::size_t k_;
  };
  const_iterator begin() const { return {this, 0}; }
  const_iterator end() const { return {this, size()}; }

 private:
  io::RecordFile file_;
};

}  // namespace mirrorcal::calibration
