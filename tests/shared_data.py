"""What the tests need of the shared real data (../shared/data), skipped with a reason naming where it was
looked for when it is missing (a bare clone passes ``make test``; conftest.py's hook skips on MissingDataError)."""

import pytest


def require_bunny() -> None:
    """Skip, naming where it was looked for, when the Stanford bunny of the shared data is missing: for a test that
    reaches it through the command line (whose exit status hides the MissingDataError conftest.py's hook skips on)."""
    from rangekit.sim.scene.zoo import bunny_path, data_folders

    if not bunny_path().is_file():
        pytest.skip(f"the Stanford bunny is not in {', '.join(str(f) for f in data_folders())}")
