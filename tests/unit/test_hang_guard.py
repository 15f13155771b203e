"""The suite's hang guard (pyproject.toml, pytest-timeout): a test that
hangs must fail with its threads' stacks and let the run go on, not hold
the suite until CI's own limit ends it with nothing said."""

pytest_plugins = ["pytester"]


def test_every_test_has_a_hang_guard(request):
    assert request.config.pluginmanager.hasplugin("timeout"), \
        "pytest-timeout is not loaded (pip install -c constraints.txt -e '.[test]')"
    assert 0 < float(request.config.getini("timeout")) <= 900
    assert request.config.getini("timeout_method") == "signal"


def test_the_guard_fails_a_test_that_hangs(pytester):
    pytester.makepyfile("""
        import time
        def test_hangs():
            time.sleep(60)
    """)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-o", "timeout=0.5",
                                           timeout=120)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*Timeout*"])
