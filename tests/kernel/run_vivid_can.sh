#!/bin/sh
# `mirrorcal run` with a CAN IMU and a V4L2 camera on a real kernel: rig_feeder plays a simulated
# rig live (IMU as MM7.10 frames on vcan0, frames through vivid's loop-back, /dev/video0), mirrorcal
# calibrates from them, and rig_feeder checks the result against the rig's truth.
#
#   run_vivid_can.sh SCENARIO SEED SECONDS K [--record | RUN OPTION...]
# SECONDS of data (mirrorcal's --duration); K: the tolerance in reported sigmas. --record: `mirrorcal
# record` from the devices instead, then `mirrorcal calibrate` on the recording. The sensor files
# (imu.yaml, camchain.yaml, mirrorcal.yaml of `mirrorcal record --scenario SCENARIO --seed SEED`)
# and guest_rig_feeder are in /data; mirrorcal is on the PATH or in /data (a static build for a board).
set -u
scenario=$1 seed=$2 seconds=$3 k=$4
shift 4
mirrorcal=mirrorcal
[ -x /data/mirrorcal ] && mirrorcal=/data/mirrorcal
command=run out=/tmp/out
if [ "${1:-}" = --record ]; then
  command=record out=/tmp/rec
  shift
fi
fail() { echo "run_vivid_can: $*"; cat /tmp/feeder.log /tmp/run.log 2>/dev/null; exit 1; }

/data/guest_rig_feeder play "$scenario" "$seed" $((seconds + 2)) >/tmp/feeder.log 2>&1 &
feeder=$!
# The feeder simulates the rig and sets vivid up first (seconds under emulation).
while [ ! -e /tmp/feeder-ready ]; do
  kill -0 $feeder 2>/dev/null || fail "the feeder ended before it was ready"
  sleep 0.1
done
"$mirrorcal" $command --imu can:vcan0 --camera /dev/video0:grey --sensors /data --out $out \
  --duration "$seconds" "$@" >/tmp/run.log 2>&1 &
run=$!
# mirrorcal prints its first line once its devices are open; then the rig starts moving.
while ! grep -qs "^mirrorcal $command:" /tmp/run.log; do
  kill -0 $run 2>/dev/null || break
  sleep 0.1
done
touch /tmp/go
wait $run
status=$?
wait $feeder
feeder_status=$?
cat /tmp/feeder.log /tmp/run.log
[ "$status" -eq 0 ] || fail "mirrorcal $command exited with $status"
[ "$feeder_status" -eq 0 ] || fail "the feeder failed"
# A camera trigger (a GPIO output, --trigger CHIP:LINE) must have fired through the run.
case " $* " in
  *" --trigger "*) grep -Eq "^trigger: [1-9][0-9]* pulses" /tmp/run.log || fail "the trigger never fired" ;;
esac
# The live feedback: what is still uncertain and what motion helps, while the rig moves.
if [ $command = run ]; then
  grep -Eq "^live [0-9]+ s: (still uncertain|converged|the rig hardly moved)" /tmp/run.log ||
    fail "run printed no live feedback"
fi
if [ $command = record ]; then
  "$mirrorcal" calibrate /tmp/rec --out /tmp/out || fail "mirrorcal calibrate failed on the recording"
fi
/data/guest_rig_feeder check "$scenario" /tmp/out "$k" || fail "the calibration is not within $k sigmas of the truth"
echo "run_vivid_can: passed"
