"""The scene's ``[method]`` table as a dataclass: the keys every method reads, and the
method's own options (its package's options dataclass, ``methods/<name>/options.py``)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from ..methods import registry

#: the [method] keys every method reads (the Method's own fields)
COMMON_METHOD_KEYS = ("name", "rtol", "atol", "integrator", "size_distribution")


@dataclass(frozen=True)
class Method:
    """Numerical method: its name, the keys every method reads (the tolerances rtol [-] and
    atol [-] on the scaled state, the per-cell integrator, which the cNMC ignores, and the
    size_distribution reconstruction of d10/d50/d90 and psd.csv, docs/physics.md section
    11.1: "support", "semi-infinite" or, for the Laguerre ROM, "expansion"; None: the
    method's first, "support"; the cNMC takes none), and ``options``, the method's own keys (its package's options dataclass; None: that method's
    defaults). The TOML table stays flat: the scene routes each key to these fields or to
    the method's options, and refuses a key of another method."""
    name: str
    rtol: float = 1.0e-8
    atol: float = 1.0e-14
    integrator: str = "auto"
    size_distribution: str | None = None
    options: Any = field(default=None, metadata={"table": "the method's own keys"})

    def __post_init__(self):
        if self.options is None:
            object.__setattr__(self, "options", registry.METHODS[self.name].options_class())

    def replaced(self, **changes) -> "Method":
        """A copy with keys replaced, common or the method's own. A new ``name`` starts from
        that method's defaults and keeps the values of the keys both methods take. A key the
        method does not take is a TypeError naming it."""
        common = {k: changes.pop(k) for k in list(changes) if k in COMMON_METHOD_KEYS}
        name = common.get("name", self.name)
        cls = registry.METHODS[name].options_class
        own = tuple(f.name for f in dataclasses.fields(cls))
        unknown = sorted(set(changes) - set(own))
        if unknown:
            raise TypeError(f"the {name} method takes no [method] key {unknown[0]!r}; it "
                            f"takes: {', '.join(COMMON_METHOD_KEYS + own)}")
        kept = {k: getattr(self.options, k) for k in own
                if name != self.name and hasattr(self.options, k)}
        options = (dataclasses.replace(self.options, **changes) if name == self.name
                   else cls(**(kept | changes)))
        if name != self.name and "size_distribution" not in common and (
                self.size_distribution not in registry.METHODS[name].distributions):
            common["size_distribution"] = None      # the new method's default
        return dataclasses.replace(self, **common, options=options)
