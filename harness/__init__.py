"""The co-simulation harness on fmpy: scenes, masters, the monolithic reference, reports,
and the ``lever`` command line."""
