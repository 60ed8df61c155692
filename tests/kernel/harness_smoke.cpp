// The harness itself: the modules named by the test are loaded, the setup commands ran (vcan0 is
// up), and a frame sent on vcan0 comes back to a second raw socket, on the guest's real kernel.
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>
#include <fstream>

#include "guest_check.hpp"

namespace {

int open_raw(const char* ifname) {
  const int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = static_cast<int>(if_nametoindex(ifname));
  if (fd < 0 || addr.can_ifindex == 0 ||
      bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0)
    return -1;
  return fd;
}

}  // namespace

int main() {
  GUEST_CHECK(std::ifstream("/sys/module/vcan/initstate").good());
  GUEST_CHECK(std::ifstream("/sys/module/can_raw/initstate").good());
  const int tx = open_raw("vcan0");
  const int rx = open_raw("vcan0");
  if (GUEST_CHECK(tx >= 0 && rx >= 0)) {
    can_frame out{};
    out.can_id = 0x123;
    out.len = 3;
    std::memcpy(out.data, "\x01\x02\x03", 3);
    GUEST_CHECK(write(tx, &out, sizeof(out)) == static_cast<ssize_t>(sizeof(out)));
    can_frame in{};
    GUEST_CHECK(read(rx, &in, sizeof(in)) == static_cast<ssize_t>(sizeof(in)));
    GUEST_CHECK(in.can_id == 0x123 && in.len == 3 && std::memcmp(in.data, out.data, 3) == 0);
  }
  return mirrorcal::guest::finish("harness_smoke");
}
