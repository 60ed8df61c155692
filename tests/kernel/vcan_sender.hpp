// The sending side of a CAN bus for the guest programs: a plain raw socket on the interface, a
// different program's view of the bus than the driver under test.
#pragma once

#include <linux/can.h>
#include <net/if.h>
#include <sys/socket.h>
#include <unistd.h>

namespace mirrorcal::guest {

// A raw CAN socket bound to ifname; -1 if it cannot be opened.
inline int open_sender(const char* ifname) {
  const int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(if_nametoindex(ifname));
  if (fd < 0 || bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    if (fd >= 0) close(fd);
    return -1;
  }
  return fd;
}

}  // namespace mirrorcal::guest
