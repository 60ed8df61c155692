// Whether this unit is built under AddressSanitizer: MIRRORCAL_ASAN is 1 then, 0 otherwise. GCC
// says so with __SANITIZE_ADDRESS__, clang with __has_feature(address_sanitizer) only.
#pragma once

#if defined(__SANITIZE_ADDRESS__)
#define MIRRORCAL_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define MIRRORCAL_ASAN 1
#endif
#endif
#ifndef MIRRORCAL_ASAN
#define MIRRORCAL_ASAN 0
#endif
