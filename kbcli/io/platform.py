"""The platform that kbcli's numbers depend on to the last bit.

Same inputs and seed give the same numbers on one platform, byte for byte. Across platforms they
can differ in the last bit (numpy's SIMD kernels and OpenBLAS's matrix kernels are chosen per CPU),
and a learning run in ``dynamics`` mode grows that ulp into another model. :func:`fingerprint`
names what decides those bits; ``make data`` stores it in ``data/platform.json``, and the rebuild
test holds a rebuild to the stored bytes only on that platform.

``python -m kbcli.io.platform [-o FILE]`` prints it as JSON (or writes it atomically).
"""

from __future__ import annotations

import json
import platform as _platform
import sys
from importlib import metadata

#: Libraries whose compiled code computes kbcli's numbers.
LIBRARIES = ("numpy", "scipy", "scikit-learn", "pymunk", "h5py")


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _simd() -> list[str]:
    """numpy's dispatch targets that this CPU has (what ``numpy.show_runtime`` calls *found*)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]


def _blas() -> list[dict]:
    """Each loaded BLAS: its implementation, version and the CPU kernel family it chose."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return []
    import numpy  # noqa: F401  (load numpy's and scipy's BLAS, so that the answer does not
    import scipy.linalg  # noqa: F401  depend on what the caller imported before)

    return sorted(({k: d.get(k) for k in ("internal_api", "version", "architecture")}
                   for d in threadpool_info() if d.get("user_api") == "blas"),
                  key=lambda d: json.dumps(d, sort_keys=True))


def fingerprint() -> dict:
    """What decides kbcli's numbers to the last bit (module docstring): the machine's
    architecture, Python, the versions of the numeric libraries, numpy's SIMD targets and the
    BLAS kernels. Two platforms with the same fingerprint give the same bytes."""
    return {
        "machine": _platform.machine(),
        "python": ".".join(map(str, sys.version_info[:3])),
        "libraries": {name: _version(name) for name in LIBRARIES},
        "numpy_simd": _simd(),
        "blas": _blas(),
    }


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    text = json.dumps(fingerprint(), indent=2, sort_keys=True) + "\n"
    if not args:
        sys.stdout.write(text)
        return 0
    if len(args) != 2 or args[0] not in ("-o", "--output"):
        sys.stderr.write("usage: python -m kbcli.io.platform [-o FILE]\n")
        return 2
    from kbcli.io.atomic import atomic_path

    with atomic_path(args[1]) as tmp, open(tmp, "w") as fh:
        fh.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
