"""The co-simulation harness on fmpy, in layers that use only the layers below them
(docs/architecture.md): ``description`` (scenes) -> ``engine`` (components, system,
masters, run, traces, guard) -> ``judges`` (monolithic reference, metrics, stability,
validation) -> ``formats`` (SSP, OSP, container, reference traces, reports, compliance)
-> ``peers`` (other engines) -> ``studies`` (bench, sweep, stability map, measured, engines) -> ``api``
-> ``cli``."""
