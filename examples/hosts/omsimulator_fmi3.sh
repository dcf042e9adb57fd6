#!/bin/sh
# KAVZ-685's FMI 3.0 editions in OMSimulator's command line, weakly coupled (FMI 3.0
# Co-Simulation).
#
# Run with OMSIMULATOR naming the command, `lever` on PATH (or LEVER naming it):
#     OMSIMULATOR=/path/to/OMSimulator sh examples/hosts/omsimulator_fmi3.sh RESULT.csv
#     lever validate --result RESULT.csv kavz685
set -eu
STEP=0.1e-3
out=$(realpath "$1")
rm -f "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"${LEVER:-lever}" export-ssp kavz685 --set experiment.fmi=3 --set experiment.step=$STEP \
    --out "$tmp/kavz685.ssp" >/dev/null
cd "$tmp"
# --directionalDerivatives=false: OMSimulator's FMI library (fmi4c) looks for FMI 3.0's
# providesDirectionalDerivatives under FMI 2.0's spelling (providesDirectionalDerivative),
# finds none, and its solver of the algebraic loop between the FMUs then fails
"$OMSIMULATOR" --stopTime=10 --tolerance=1e-6 --directionalDerivatives=false --tempDir="$tmp" \
    --resultFile="$out" kavz685.ssp
test -s "$out" || { echo "OMSimulator wrote no result" >&2; exit 1; }
