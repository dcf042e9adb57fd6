#!/bin/sh
# KAVZ-685 in OMSimulator's command line, weakly coupled: its fixed-step master on the FMUs'
# FMI 2.0 Co-Simulation, as `lever export-ssp` writes the archive.
#
# Run with OMSIMULATOR naming the command, `lever` on PATH (or LEVER naming it):
#     OMSIMULATOR=/path/to/OMSimulator sh examples/hosts/omsimulator_weak.sh RESULT.csv
#     lever validate --result RESULT.csv kavz685
set -eu
# the master sets each FMU's inputs from the outputs of the step before: at the scene's 1 ms
# that lag fails the verdict
STEP=0.1e-3
out=$(realpath "$1")
rm -f "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"${LEVER:-lever}" export-ssp kavz685 --set experiment.step=$STEP --out "$tmp/kavz685.ssp" >/dev/null
cd "$tmp"
# the command line's own --stopTime (1 s) and --tolerance replace the archive's: give both
"$OMSIMULATOR" --stopTime=10 --tolerance=1e-6 --tempDir="$tmp" --resultFile="$out" kavz685.ssp
# the command line exits 0 even when initialisation fails: its result file says whether it ran
test -s "$out" || { echo "OMSimulator wrote no result" >&2; exit 1; }
