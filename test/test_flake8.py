"""ament_flake8 over the package: the lint every ament_python package is held to."""

import pytest


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8(lint_paths):
    flake8 = pytest.importorskip('ament_flake8.main', reason='ament_flake8 is not installed '
                                 '(.ci/requirements.txt installs it and its plugins)')
    rc, errors = flake8.main_with_errors(argv=lint_paths)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)
