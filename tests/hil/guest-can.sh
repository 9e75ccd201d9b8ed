#!/bin/bash
# Guest side of hil.can: the CAN backend on vcan0 in classic and FD mode, checked by candump too.
#
#   guest-can.sh HIL_CAN_BINARY
set -u
source "$(dirname "$0")/guest-devices.sh"
make_vcan || exit 1

candump -L vcan0 > /tmp/candump.log 2>&1 &
candump_pid=$!
sleep 0.5
"$1" --gtest_filter='*PoseFrame*'
rc=$?
sleep 0.5
kill "$candump_pid"
wait "$candump_pid" 2> /dev/null
echo "candump saw:"
cat /tmp/candump.log
# can-utils' own reading of the same bus: the three classic frames of body 1 and its FD frame
# with the bit-rate switch flag (bit 0 of the flags digit after "##").
for expected in ' vcan0 303#' ' vcan0 304#' ' vcan0 305#' ' vcan0 381##[13579BDF]'; do
    if ! grep -q -- "$expected" /tmp/candump.log; then
        echo "FAILED: candump did not see '$expected'"
        rc=1
    fi
done
[ "$rc" -eq 0 ] || exit "$rc"

# The fault paths, each restoring vcan0 for the next.
exec "$1" --gtest_filter='-*PoseFrame*'
