#!/bin/sh
# `run` stops on SIGINT, SIGTERM and SIGHUP (a closed terminal) with its final report and exit 0.
# Usage: check_stop_signals.sh EDGETRACK WORKDIR
set -u
edgetrack=$1 work=$2
mkdir -p "$work"
for signal in INT TERM HUP; do
    out="$work/run_$signal.txt"
    "$edgetrack" run --board sim --frames 1000000 >"$out" 2>&1 &
    pid=$!
    sleep 1
    kill -s "$signal" "$pid"
    wait "$pid"
    code=$?
    if [ "$code" -ne 0 ] || ! grep -q "^flash errors" "$out"; then
        echo "SIG$signal: exit $code, final report missing:"
        tail -5 "$out"
        exit 1
    fi
    echo "ok: SIG$signal ends run with its report"
done
