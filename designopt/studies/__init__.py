"""The study registry: ``STUDIES[name]`` is a :class:`~designopt.studies.base.Study`.

Config, pipeline and CLI reach studies only through this registry. Every sub-package of
this folder that defines ``STUDY`` (one Study, or a tuple of them) is registered when the registry is imported (adding a
study is adding a folder); a user's own study registers with :func:`register` (before
loading a config that names it).
"""

from __future__ import annotations

from designopt.studies.base import STREAMS, Study, StudySettings, key_data, streams

STUDIES: dict[str, Study] = {}


def register(study: Study) -> Study:
    """Add ``study`` to the registry (a name may be registered once)."""
    if study.name in STUDIES and STUDIES[study.name] is not study:
        raise ValueError(f"a study named {study.name!r} is already registered")
    STUDIES[study.name] = study
    return study


def get(name: str) -> Study:
    """The registered study ``name``; ValueError listing the known ones otherwise."""
    try:
        return STUDIES[name]
    except KeyError:
        raise ValueError(f"unknown study {name!r}; known: {sorted(STUDIES)}") from None


def _builtins() -> None:
    import importlib
    import pkgutil

    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.ispkg:
            mod = importlib.import_module(f"{__name__}.{info.name}")
            found = getattr(mod, "STUDY", ())
            for st in found if isinstance(found, tuple) else (found,):
                register(st)


_builtins()

__all__ = ["STREAMS", "STUDIES", "Study", "StudySettings", "get", "key_data", "register", "streams"]
