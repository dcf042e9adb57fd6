"""Lever-articulated coupling models: the physics (``lever.physics``) and the thin FMI
adapters on it (``lever.fmus``).

Every import inside this package is relative: the FMU build copies the whole package
into each FMU under a name of its own, so that two of our FMUs loaded into one Python
process never share (or shadow) each other's modules.
"""
__version__ = "0.1.0"
