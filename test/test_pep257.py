"""ament_pep257 over the package: docstrings in the ament convention."""

import pytest


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257(lint_paths):
    pep257 = pytest.importorskip('ament_pep257.main', reason='ament_pep257 is not '
                                 'installed (.ci/requirements.txt installs it)')
    assert pep257.main(argv=lint_paths) == 0, 'Found code style errors / warnings'
