"""Where things are in the repository."""
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESOURCES = ROOT / "resources"
SCENES = RESOURCES / "scenes"
DATA = RESOURCES / "data"
BUILD = ROOT / "build"
FMUS = BUILD / "fmus"
RESULTS = ROOT / "results"
