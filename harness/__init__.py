"""The co-simulation harness on fmpy, in layers that use only the layers below them
(docs/architecture.md): ``description`` (scenes) -> ``engine`` (components, system,
masters, run, traces, guard) -> ``judges`` (monolithic reference, metrics, stability,
validation) -> ``formats`` (SSP, OSP, container, reference traces, reports, compliance)
-> ``peers`` (other engines) -> ``studies`` (bench, sweep, stability map, measured, engines) -> ``cli``."""
from importlib import import_module

#: where the modules of the flat harness went: ``from harness import masters`` (and the
#: other old names) keeps working for code written before the layers
MOVED = {"scene": "harness.description.scene", "component": "harness.engine.component",
         "system": "harness.engine.system", "masters": "harness.engine.masters", "run": "harness.engine.run",
         "traces": "harness.engine.traces", "divergence": "harness.engine.guard",
         "reference": "harness.judges.monolithic", "freewheel": "harness.judges.rectifier",
         "metrics": "harness.judges.metrics", "stability": "harness.judges.stability",
         "validate": "harness.judges.validation", "crosscheck": "harness.formats.reference_traces",
         "ssp": "harness.formats.ssp", "osp": "harness.formats.osp", "container": "harness.formats.container",
         "peers": "harness.peers", "report": "harness.formats.report",
         "badinputs": "harness.formats.badinputs", "bench": "harness.studies.bench",
         "sweep": "harness.studies.sweep", "stabilitymap": "harness.studies.stabilitymap",
         "measured": "harness.studies.measured", "engines": "harness.studies.engines",
         "cases": "harness.studies.cases"}
# (the flat harness's ``studies`` module is ``harness.studies.decisions``: ``harness.studies``
# now names the layer's package)


def __getattr__(name: str):
    if name in MOVED:
        return import_module(MOVED[name])
    raise AttributeError(f"module 'harness' has no attribute '{name}'")
