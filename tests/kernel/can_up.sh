#!/bin/sh
# The package's can-up (deploy/can-up, run by mirrorcal.service before the run) on a real kernel,
# with iproute2's ip as a board has it: a CAN interface run.conf names is brought up when down and
# left alone when up; a run.conf naming an SPI IMU needs nothing; a missing interface is refused
# with a message naming it. vcan has no bitrate, which can-up knows.
set -u
# iproute2's ip (HOST_TOOLS): busybox's shell would run its own ip applet, which knows no CAN.
export IP=/bin/ip
ip() { /bin/ip "$@"; }
fail() { echo "can_up: $1"; exit 1; }
up() { ip link show "$1" | grep -q '[<,]UP[,>]'; }
ip link add dev vcan1 type vcan || fail "cannot add vcan1"
up vcan1 && fail "vcan1 is up before can-up"
printf 'imu: can:vcan1   # the MM7.10\ncamera: /dev/video0\n' >/tmp/can.conf
sh /data/can-up /tmp/can.conf 500000 || fail "can-up failed on a down vcan1"
up vcan1 || fail "can-up left vcan1 down"
sh /data/can-up /tmp/can.conf 500000 || fail "can-up failed on vcan1 already up"
printf 'imu: spi:/dev/spidev0.0\n' >/tmp/spi.conf
sh /data/can-up /tmp/spi.conf 500000 || fail "can-up failed for an SPI IMU"
printf 'imu: can:can7\n' >/tmp/missing.conf
sh /data/can-up /tmp/missing.conf 500000 2>/tmp/missing.log && fail "can-up took a missing can7"
grep -q "can7" /tmp/missing.log || fail "the refusal does not name can7: $(cat /tmp/missing.log)"
echo "can_up: passed"
