import re

from frog_common.version import code_version


def test_code_version_names_the_package_and_the_commit():
    v = code_version('frog_common')
    assert re.fullmatch(r'frog_common (\S+)( \(git [0-9a-f]{4,}\))?', v), v
    assert v.split()[1] != 'unknown'                 # the package is installed in the workspace
    assert code_version('no_such_package').startswith('no_such_package unknown')
