"""Checks shared by the tests of the command line's bad-input contract."""


def assert_one_line_error(result, *words) -> str:
    """Exit 2, nothing on stdout, one 'fdbench: error:' line on stderr naming ``words``; the line."""
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.stdout)
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fdbench: error:"), result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]
