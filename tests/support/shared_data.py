"""What the tests need of the shared real data (../shared/data), skipped with a reason naming where it was
looked for when it is missing (a bare clone passes ``make test``; conftest.py's hook skips on MissingDataError)."""

from pathlib import Path

import pytest


def require_bunny() -> None:
    """Skip, naming where it was looked for, when the Stanford bunny of the shared data is missing: for a test that
    reaches it through the command line (whose exit status hides the MissingDataError conftest.py's hook skips on)."""
    from rangekit.sim.scene.zoo import bunny_path, data_folders

    if not bunny_path().is_file():
        pytest.skip(f"the Stanford bunny is not in {', '.join(str(f) for f in data_folders())}")


def shared_path(*parts: str) -> Path:
    """The file or folder ``parts`` of the shared real data: in the first of :func:`data_folders` holding it, else
    where it would be in the first (so ``is_file()`` finds it missing). ``RANGEKIT_DATA`` hides or moves it."""
    from rangekit.sim.scene.zoo import data_folders

    paths = [folder.joinpath(*parts) for folder in data_folders()]
    return next((p for p in paths if p.exists()), paths[0])


def require_shared(*parts: str) -> Path:
    """:func:`shared_path`, or a skip naming every folder it was looked for in when it is missing."""
    from rangekit.sim.scene.zoo import data_folders

    path = shared_path(*parts)
    if not path.exists():
        pytest.skip(f"{'/'.join(parts)} is not in {', '.join(str(f) for f in data_folders())} (the shared real data)")
    return path
