"""Names of a package loaded on first use (PEP 562), for packages a light process imports."""

import importlib
from typing import Callable, Mapping

__all__ = ['lazy_names']


def lazy_names(package: str, homes: Mapping[str, str],
               public: list) -> tuple[Callable[[str], object], Callable[[], list]]:
    """Return a package's ``__getattr__`` and ``__dir__`` for names kept in other modules.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    homes : Mapping[str, str]
        Name -> the module (absolute) that defines it; imported on the first access.
    public : list
        The package's ``__all__``.

    """
    namespace = importlib.import_module(package).__dict__

    def __getattr__(name: str) -> object:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        value = getattr(importlib.import_module(home), name)
        namespace[name] = value  # found by the next lookup without this function
        return value

    def __dir__() -> list:
        return sorted(set(namespace) | set(public))

    return __getattr__, __dir__
