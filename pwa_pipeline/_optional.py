"""Libraries that only some features need, installed by an extra of the package."""

import importlib
from types import ModuleType


def require(module: str, extra: str, feature: str) -> ModuleType:
    """Import ``module``, or raise an ImportError that names the feature that needs it and
    the extra that installs it (``pip install "pwa-pipeline[extra]"``): the library itself
    installs numpy, scipy, scikit-learn, pandas and numba only."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{feature} needs {module.split('.')[0]}, which is not installed: "
                          f'pip install "pwa-pipeline[{extra}]"') from exc
