"""What an instance must recompute before its outputs are read (its ``_dirty``): setting
values, stepping and restoring a state each mark it; reading an output clears it."""

CLEAN = 0
#: only the outputs that depend on inputs (``_compute_input_outputs``)
INPUTS_CHANGED = 1
#: everything: time, state or model changed
ALL = 2
