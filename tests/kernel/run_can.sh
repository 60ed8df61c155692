#!/bin/sh
# `mirrorcal run` on a real kernel: the program as users run it (dynamically linked, its libraries
# copied in), reading a live MM7.10 on vcan0 that guest_can simulates in real time.
/data/guest_can send 4 &
sender=$!
# The sender simulates first (seconds under emulation), then says it is ready.
while [ ! -e /tmp/sender-ready ]; do sleep 0.1; done
mirrorcal run --imu can:vcan0 --sensors /data --out /tmp/out --duration 2 >/tmp/run.log 2>&1
status=$?
cat /tmp/run.log
wait $sender || { echo "run_can: the sender failed"; exit 1; }
[ "$status" -eq 0 ] || { echo "run_can: mirrorcal run exited with $status"; exit 1; }
# About 2 s at 200 Hz (the sender catches up in bursts when the emulator lags), nothing lost, and
# the result files written.
n=$(sed -n 's/^loop: \([0-9]*\) IMU samples.*/\1/p' /tmp/run.log)
[ "${n:-0}" -ge 300 ] && [ "$n" -le 500 ] || { echo "run_can: $n samples, not about 400"; exit 1; }
grep -q "^CAN: .* 0 lost, 0 incomplete samples, 0 rejected" /tmp/run.log || { echo "run_can: losses"; exit 1; }
[ -s /tmp/out/camchain-imucam.yaml ] && [ -s /tmp/out/mirrorcal-result.yaml ] || { echo "run_can: no results"; exit 1; }
echo "run_can: passed"
