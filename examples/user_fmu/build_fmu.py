"""Build DrivenShaft.fmu from driven_shaft.py with pythonfmu (state handling declared):
``python examples/user_fmu/build_fmu.py [OUT_DIR]`` (default: beside this file)."""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def build(out_dir: Path = HERE) -> Path:
    from pythonfmu.builder import FmuBuilder

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return Path(FmuBuilder.build_FMU(HERE / "driven_shaft.py", dest=out_dir / "DrivenShaft.fmu",
                                     canGetAndSetFMUstate=True, canSerializeFMUstate=True))


if __name__ == "__main__":
    print(build(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE))
