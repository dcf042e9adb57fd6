#!/bin/sh
# KAVZ-685 in OMSimulator's command line, strongly coupled: the FMUs' FMI 2.0 Model Exchange
# under its CVODE. The export writes a weakly coupled system; this turns its fixed-step
# master into OMSimulator's variable-step solver.
#
# Run with OMSIMULATOR naming the command, `lever` on PATH (or LEVER naming it):
#     OMSIMULATOR=/path/to/OMSimulator sh examples/hosts/omsimulator_strong.sh RESULT.csv
#     lever validate --result RESULT.csv kavz685
set -eu
# OMSimulator sets the FMUs' inputs from one another's outputs only each STEP (not inside
# CVODE's right-hand side): the coupling's torques are held over it
STEP=0.1e-3
TOLERANCE=1e-7
out=$(realpath "$1")
rm -f "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"${LEVER:-lever}" export-ssp kavz685 --set experiment.step=$STEP --out "$tmp/kavz685.ssp" >/dev/null
cd "$tmp"
unzip -q kavz685.ssp SystemStructure.ssd
sed -i "s|<oms:FixedStepMaster [^>]*/>|<oms:VariableStepSolver description=\"cvode\" relativeTolerance=\"$TOLERANCE\" minimumStepSize=\"1e-12\" maximumStepSize=\"$STEP\" initialStepSize=\"1e-6\"/>|" SystemStructure.ssd
grep -q VariableStepSolver SystemStructure.ssd
zip -q kavz685.ssp SystemStructure.ssd
# the command line's --tolerance replaces the archive's (default 1e-4), and its --stopTime
# (default 1 s) the archive's 10 s
"$OMSIMULATOR" --stopTime=10 --tolerance=$TOLERANCE --tempDir="$tmp" --resultFile="$out" kavz685.ssp
test -s "$out" || { echo "OMSimulator wrote no result" >&2; exit 1; }
