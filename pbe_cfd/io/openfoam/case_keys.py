"""The ``[domain]`` keys naming an OpenFOAM case and its time, read the one way every verb
uses them: the case relative to the scene file, the time as OpenFOAM names its directories."""
from __future__ import annotations

import math
import os
import re
from pathlib import Path


def case_path(scene_path, case: str) -> str:
    """``[domain] case``, a path relative to the scene file's directory, made absolute (the
    one rule for reading and writing); ``bundled:`` names are kept."""
    if case.startswith("bundled:") or Path(case).is_absolute():
        return case
    return os.path.normpath(Path(scene_path).resolve().parent / case)


def case_time(path, time, error) -> str:
    """``[domain] time``: "latest" or a non-negative finite time in s (a number, or a string
    holding one, as OpenFOAM names its time directories); ``error(path, key, message)`` is
    the exception raised."""
    value = time
    if isinstance(time, str) and time != "latest":
        try:
            value = float(time)
        except ValueError:
            value = None
    if not (time == "latest" or (isinstance(value, (int, float)) and not isinstance(value, bool)
                                 and math.isfinite(value) and value >= 0)):
        raise error(path, "domain.time",
                    f"expected \"latest\" or a non-negative time in s, got {time!r}")
    return "latest" if time == "latest" else str(value)


def phase(path, name: str, error) -> str:
    """``[domain] phase``: the solids phase's name as in the case's fields (alpha.<phase>)."""
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise error(path, "domain.phase", "expected the solids phase's name as in the case's "
                    f"fields (alpha.<phase>), got {name!r}")
    return name
