"""Finding adapters: the built-ins (always, no installation needed) plus any object registered in the
entry-point group ``rsart.adapters`` (name = method name; value = an adapter instance, or a class or
zero-argument factory returning one). The ``rsart`` CLI uses the entry points only (rsart never
imports this package); pyproject.toml declares the built-ins there.
"""
from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any

from rsart.errors import RsartError

GROUP = "rsart.adapters"

#: method name -> "module:attribute" of the built-in adapters (the pyproject entry points say the same).
BUILTIN = {
    "paris": "baselines_adapters.paris:ParisAdapter",
    "articulatedgs": "baselines_adapters.paris:ArticulatedGSAdapter",
    "dtart": "baselines_adapters.dtart:DTArtAdapter",
    "artgs": "baselines_adapters.artgs:ArtGSAdapter",
    "reartgs": "baselines_adapters.artgs:REArtGSAdapter",
    "reartgspp": "baselines_adapters.artgs:REArtGSPlusPlusAdapter",
}


def instantiate(obj: Any) -> Any:
    """An adapter from an entry point's loaded value (instance, class or factory)."""
    if hasattr(obj, "export") and hasattr(obj, "import_run") and not isinstance(obj, type):
        return obj
    if callable(obj):
        inst = obj()
        if hasattr(inst, "export") and hasattr(inst, "import_run"):
            return inst
    raise RsartError(f"{obj!r} is not an adapter (needs export() and import_run())")


def _load_ref(ref: str) -> Any:
    import importlib

    mod, attr = ref.split(":")
    return instantiate(getattr(importlib.import_module(mod), attr))


def available(include_entry_points: bool = True) -> dict[str, Any]:
    """Method name -> adapter: the built-ins, then entry-point adapters with other names."""
    out = {name: _load_ref(ref) for name, ref in BUILTIN.items()}
    if include_entry_points:
        for ep in entry_points(group=GROUP):
            if ep.name in out:
                continue
            try:
                out[ep.name] = instantiate(ep.load())
            except Exception as e:  # a broken third-party plug-in must not break the others
                out[ep.name] = BrokenAdapter(ep.name, f"{ep.value}: {type(e).__name__}: {e}")
    return out


def get_adapter(name: str) -> Any:
    """The adapter called ``name`` (raises naming the available ones)."""
    ads = available()
    if name not in ads:
        raise RsartError(f"no adapter {name!r} (available: {', '.join(sorted(ads))})")
    ad = ads[name]
    if isinstance(ad, BrokenAdapter):
        raise RsartError(f"adapter {name!r} failed to load: {ad.error}")
    return ad


class BrokenAdapter:
    """Placeholder listed for an entry point that failed to load."""

    def __init__(self, name: str, error: str):
        self.name, self.error = name, error
        self.title, self.protocol, self.description = name, "?", f"BROKEN: {error}"

    def export(self, *a, **k):
        raise RsartError(f"adapter {self.name!r} failed to load: {self.error}")

    import_run = export
