#!/bin/sh
# Checks deploy/edgetrack.service with systemd-analyze verify (exit 77 when it is not installed).
# Usage: check_unit.sh UNIT EDGETRACK_BINARY
set -eu
if ! command -v systemd-analyze >/dev/null 2>&1; then
    echo "SKIP: systemd-analyze is not installed"
    exit 77
fi
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
# The unit names the installed path; point it at the built program so verify can check it.
sed "s|/usr/bin/edgetrack|$2|" "$1" > "$dir/edgetrack.service"
out=$(systemd-analyze verify "$dir/edgetrack.service" 2>&1) || { echo "$out"; exit 1; }
# verify prints warnings without failing: any output about this unit is a defect.
if echo "$out" | grep -q "edgetrack.service"; then
    echo "$out"
    exit 1
fi
echo "ok"
