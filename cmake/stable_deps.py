"""Give the build's dependencies a path that outlives pip's isolated build environment.

`pip install .` installs the build requirements into a new temporary environment each time
(/tmp/pip-build-env-RANDOM), so the include paths of Pinocchio, Eigen, pybind11 and NumPy change
from one install to the next, their headers are newer than the objects built last time, and
ninja compiles everything again even in a kept build folder. This script hard-links (or copies,
across file systems) the files the build reads into BUILD/deps/KEY, where KEY hashes every such
file's path and content hash from its package's RECORD: the same dependencies give the same
folder with the same file times (the build is incremental), other versions another folder (the
changed command lines make ninja rebuild everything that read them). Other keys' folders are
removed.

Run by CMakeLists.txt with the Python that builds (CMake's Python_EXECUTABLE):

    python stable_deps.py BUILD/deps

Prints three lines: the cmeel prefix (Pinocchio, Eigen, Boost, eigenpy, urdfdom), pybind11's
CMake folder and NumPy's include folder. Outside an isolated build (the dependencies are in the
target environment itself, whose paths are stable) it prints their own paths and copies nothing.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import sysconfig
from importlib import metadata
from pathlib import Path

# What the compile and link read, relative to site-packages. Not the Python packages in
# cmeel.prefix/lib/pythonX.Y: the build never imports them.
ROOTS = ("cmeel.prefix/", "pybind11/include/", "pybind11/share/cmake/", "numpy/_core/include/")
SKIP = ("cmeel.prefix/lib/python",)
OUTPUTS = ("cmeel.prefix", "pybind11/share/cmake/pybind11", "numpy/_core/include")


def _files() -> dict[str, tuple[Path, str]]:
    """The files under ROOTS: path relative to site-packages -> (source file, RECORD hash)."""
    found: dict[str, tuple[Path, str]] = {}
    for dist in metadata.distributions():
        for entry in dist.files or []:
            rel = entry.as_posix()
            if not rel.startswith(ROOTS) or rel.startswith(SKIP) or entry.hash is None:
                continue
            # The first on sys.path wins, as for an import.
            found.setdefault(rel, (Path(str(dist.locate_file(entry))), entry.hash.value))
    return found


def _site(files: dict[str, tuple[Path, str]], top: str) -> Path:
    """The site-packages folder that holds `top` (cmeel.prefix, pybind11, numpy)."""
    for rel, (source, _) in files.items():
        if rel.startswith(top + "/"):
            return Path(str(source)[: -len(rel)])
    sys.exit(f"stable_deps.py: no installed files under {top}/ (is the package installed?)")


def _mirror(files: dict[str, tuple[Path, str]], deps: Path) -> Path:
    listing = "".join(f"{rel} {digest}\n" for rel, (_, digest) in sorted(files.items()))
    key = hashlib.sha256(listing.encode()).hexdigest()[:16]
    target = deps / key
    if not target.is_dir():
        partial = deps / f".{key}.partial"
        shutil.rmtree(partial, ignore_errors=True)
        for rel, (source, _) in files.items():
            dest = partial / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(source, dest)
            except OSError:  # another file system, or no hard links there
                shutil.copy2(source, dest)
        (partial / "RECORD").write_text(listing)
        partial.rename(target)  # only a complete folder gets its key's name
    for other in deps.iterdir():
        if other != target:
            shutil.rmtree(other, ignore_errors=True)
    return target


def main() -> int:
    if len(sys.argv) != 2:
        sys.exit("usage: stable_deps.py DEPS_FOLDER")
    files = _files()
    sites = {top: _site(files, top.split("/")[0]) for top in OUTPUTS}
    own = {Path(sysconfig.get_paths()[k]).resolve() for k in ("purelib", "platlib")}
    if all(site.resolve() in own for site in sites.values()):
        bases = sites  # not an isolated build: the target environment's own, stable paths
    else:
        deps = Path(sys.argv[1])
        deps.mkdir(parents=True, exist_ok=True)
        root = _mirror(files, deps)
        bases = dict.fromkeys(OUTPUTS, root)
    for top in OUTPUTS:
        print((bases[top] / top).as_posix())
    return 0


if __name__ == "__main__":
    sys.exit(main())
