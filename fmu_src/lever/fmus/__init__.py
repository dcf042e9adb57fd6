"""Thin FMI 2.0 co-simulation adapters (pythonfmu) on ``lever.physics``."""
