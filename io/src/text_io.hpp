// Numbers in the recording's text files: written as the shortest decimal that reads back as the
// same double (std::to_chars), read with std::from_chars, so a written-then-read recording is
// bit-identical. Internal to io.
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

namespace mirrorcal::io::text {

// Appends v to out, shortest round-trip form.
inline void append(std::string& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

inline void append(std::string& out, std::int64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

inline std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

// The whole of s as a number; false on anything else (empty, trailing characters, out of range).
// Non-finite values are read (so the caller can say that they are not finite).
inline bool parse(std::string_view s, double& v) {
  s = trim(s);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

inline bool parse(std::string_view s, std::int64_t& v) {
  s = trim(s);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

inline std::string quoted(std::string_view s) {
  constexpr std::size_t kMax = 40;  // long garbage is cut in messages
  std::string q = "'";
  for (char c : s.substr(0, kMax)) q += (c >= ' ' && c <= '~') ? c : '?';
  if (s.size() > kMax) q += "...";
  return q + "'";
}

}  // namespace mirrorcal::io::text
