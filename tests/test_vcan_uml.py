"""The vcan tests (tests/inside_uml) on a real Linux vcan0: run inside User-Mode Linux when this kernel has none,
and tools/vcan-uml itself as a user sees it (exit status, output, vcan1, timeout, clear errors).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest
from vcan_harness import has_vcan, run_in_uml, uml_missing


def needs_uml() -> None:
    if reason := uml_missing():
        pytest.skip(reason)


@pytest.fixture(scope="session")
def inside_uml_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path]:
    """tests/inside_uml run once per session inside UML: the result and its JUnit report."""
    if has_vcan():
        pytest.skip("this machine has a vcan0: tests/inside_uml ran directly on it")
    needs_uml()
    report = tmp_path_factory.mktemp("inside_uml") / "junit.xml"
    result = run_in_uml([sys.executable, "-m", "pytest", "tests/inside_uml", "-q", "--color=no",
                         "-p", "no:cacheprovider", "-p", "no:hypothesispytest", f"--junitxml={report}"])
    return result, report


@pytest.mark.vcan
def test_vcan_tests_pass_inside_uml(inside_uml_run):
    result, report = inside_uml_run
    assert result.returncode == 0, f"tests/inside_uml failed inside UML:\n{result.stdout}"
    suite = ElementTree.parse(report).getroot().find("testsuite")
    assert suite is not None, result.stdout
    ran, skipped = int(suite.get("tests")), int(suite.get("skipped"))
    assert ran > 0 and skipped == 0, f"inside UML {ran} vcan tests ran and {skipped} were skipped:\n{result.stdout}"


@pytest.mark.vcan
def test_vcan_uml_streams_the_commands_output_and_returns_its_status():
    needs_uml()
    result = run_in_uml(["sh", "-c", 'ip -br link show type vcan; echo "inside=$APPSIM_INSIDE_UML $PWD"; exit 3'],
                        vcan=2)
    assert result.returncode == 3, result.stdout
    interfaces = [line.split()[0] for line in result.stdout.splitlines() if line.startswith("vcan")]
    assert interfaces == ["vcan0", "vcan1"], result.stdout
    assert f"inside=1 {Path(__file__).resolve().parent.parent}" in result.stdout


@pytest.mark.vcan
def test_vcan_uml_stops_a_command_that_outlives_its_timeout():
    needs_uml()
    result = run_in_uml(["sleep", "60"], timeout=1)
    assert result.returncode == 124
    assert "sleep 60 did not finish within 1 s (--timeout)" in result.stdout


@pytest.mark.vcan
def test_vcan_uml_says_how_to_install_uml_when_missing():
    result = run_in_uml(["true"], options=["--kernel", "/nonexistent/linux"])
    assert result.returncode == 125
    assert "apt-get install user-mode-linux" in result.stdout


@pytest.mark.vcan
def test_vcan_uml_says_so_when_the_kernel_has_no_vcan(tmp_path):
    needs_uml()
    result = run_in_uml(["true"], options=["--modules", str(tmp_path)])
    assert result.returncode == 125
    assert "no vcan in kernel" in result.stdout and str(tmp_path) in result.stdout
