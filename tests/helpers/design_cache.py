"""Generated design folders built once per test module, keyed by configuration and memory init."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path


class DesignCache:
    """Generate each :class:`sim/pwas_designs.DesignConfig` once under ``root`` and return its folder.

    ``cache(cfg)`` (or ``cache(cfg, "inline")``, the default memory init) generates with the
    configuration's options; ``cache(cfg, "readmemh")`` with ``memory_init="readmemh"`` in a folder
    of its own.
    """

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self._made: dict[str, Path] = {}

    def __call__(self, cfg, memory_init: str | None = None) -> Path:
        default = memory_init in (None, "inline")
        key = cfg.name if default else f"{cfg.name}-{memory_init}"
        if key not in self._made:
            if not default:
                cfg = replace(cfg, options={**cfg.options, "memory_init": memory_init})
            cfg.generate(self.root / key)
            self._made[key] = self.root / key
        return self._made[key]


def parallel_twin(cfg, name: str, **extra_options):
    """The configuration ``cfg`` without its ``architecture`` option (so parallel), named ``name``,
    with ``extra_options`` added."""
    opts = {k: v for k, v in cfg.options.items() if k != "architecture"} | extra_options
    return replace(cfg, name=name, options=opts)
