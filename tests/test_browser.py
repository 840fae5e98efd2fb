"""A student's first hour in a real browser: JupyterLab on 127.0.0.1, driven by Playwright with Debian's Chromium.

EX1: Run All with the starter (the check says what to fix), the fix typed into the firmware cell's editor, Run All again
(full marks), the potentiometer turned (LCD line 3 follows). EX3 with a typo: the board says why in the check's words,
numbered as in the cell, and the check cell still runs. 00 and 01: their pictures, and the try that ends each, first as
shipped, then with a right answer typed in. Screenshots go to $APPSIM_ARTIFACTS (out/screenshots).
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import nbformat
import pytest

KIT = Path(__file__).resolve().parent.parent
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-quic"]
ARTIFACTS = Path(os.environ.get("APPSIM_ARTIFACTS", KIT / "out" / "screenshots"))
SERVER_START_S = 180                # a first start on a busy 2-core machine takes tens of seconds
PAGE_S = 180                        # a first JupyterLab page load took ~35 s there
RUN_ALL_S = 300
# JupyterLab's own settings for this run: every cell kept in the page (so the editor and outputs can be found), no
# news or update checks (no network, no pop-ups)
SETTINGS = {"@jupyterlab/notebook-extension/tracker.jupyterlab-settings": {"windowingMode": "none"},
            "@jupyterlab/apputils-extension/notification.jupyterlab-settings": {"fetchNews": "false",
                                                                                "checkForUpdates": False}}
TYPO = ("CANSetFilter(CAN_FILTER_B1_F1,", "CANSetFliter(CAN_FILTER_B1_F1,")

playwright = pytest.importorskip("playwright.sync_api", reason="needs Playwright for Python (pip install playwright)")
pytest.importorskip("jupyterlab", reason="needs JupyterLab (pip install jupyterlab)")
pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason=f"needs Debian's Chromium at {CHROMIUM} "
                                                              "(apt-get install chromium)")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Lab:
    """A JupyterLab server on 127.0.0.1 over a folder of notebooks, its kernels running this checkout's Python."""

    def __init__(self, root: Path, home: Path):
        self.root = root
        self.port = free_port()
        self.token = secrets.token_hex(16)
        settings = home / "settings"
        for name, values in SETTINGS.items():
            (settings / name).parent.mkdir(parents=True, exist_ok=True)
            (settings / name).write_text(json.dumps(values))
        env = {**os.environ, "JUPYTERLAB_SETTINGS_DIR": str(settings), "JUPYTERLAB_WORKSPACES_DIR": str(home / "ws"),
               "JUPYTER_RUNTIME_DIR": str(home / "runtime"), "JUPYTER_CONFIG_DIR": str(home / "config")}
        if sys.prefix != sys.base_prefix:       # a venv over the Python that has the widgets: their extension is there
            base = Path(sys.base_prefix) / "share" / "jupyter"
            env["JUPYTER_PATH"] = os.pathsep.join(filter(None, [os.environ.get("JUPYTER_PATH"), str(base)]))
        command = [sys.executable, "-m", "jupyterlab", "--no-browser", "--ip=127.0.0.1", f"--port={self.port}",
                   f"--IdentityProvider.token={self.token}", "--LabApp.expose_app_in_browser=True",
                   f"--ServerApp.root_dir={root}", *(["--allow-root"] if os.geteuid() == 0 else [])]
        self.log = (home / "jupyterlab.log").open("wb")
        self.process = subprocess.Popen(command, cwd=root, env=env, stdout=self.log, stderr=subprocess.STDOUT)

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self.port}/{path}?token={self.token}"

    def wait(self) -> None:
        deadline = time.monotonic() + SERVER_START_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"JupyterLab exited with {self.process.returncode}:\n{self.output()}")
            try:
                with urllib.request.urlopen(self.url("api/status"), timeout=5):
                    return
            except (urllib.error.URLError, OSError):
                time.sleep(0.5)
        raise TimeoutError(f"JupyterLab did not answer in {SERVER_START_S} s:\n{self.output()}")

    def output(self) -> str:
        self.log.flush()
        return Path(self.log.name).read_text(errors="replace")[-4000:]

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.log.close()


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Iterator[Lab]:
    root = tmp_path_factory.mktemp("notebooks")
    for name in ("ex1", "ex3", "00_can_in_15_minutes", "01_bit_timing"):
        shutil.copy(KIT / "notebooks" / f"{name}.ipynb", root)
    notebook = nbformat.read(root / "ex3.ipynb", as_version=4)
    [firmware] = [cell for cell in notebook.cells if "firmware" in cell.metadata.get("tags", [])]
    assert firmware.source.count(TYPO[0]) == 1
    firmware.source = firmware.source.replace(*TYPO)
    nbformat.write(notebook, root / "ex3_typo.ipynb")
    server = Lab(root, tmp_path_factory.mktemp("jupyter"))
    try:
        server.wait()
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def browser():
    with playwright.sync_playwright() as driver:
        chromium = driver.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


# The notebook's panel in JupyterLab's page, found by its path (whatever tab is current), once the page has one.
PANEL = ("window.jupyterapp && [...window.jupyterapp.shell.widgets('main')].find("
         "w => w.context && w.context.path === path)")


class Notebook:
    """One notebook open in JupyterLab's page, as a student sees and uses it."""

    def __init__(self, page, lab: Lab, name: str):
        self.page = page
        self.name = name
        self.path = f"{name}.ipynb"
        page.goto(lab.url(f"lab/tree/{self.path}") + "&reset", timeout=PAGE_S * 1000)     # reset: no other tabs
        self.wait_until("panel && panel.sessionContext.session?.kernel?.status === 'idle'", PAGE_S)

    def evaluate(self, expression: str, argument: object = None):
        """`expression` in the page, with `panel` the notebook's panel and `argument` as `argument`."""
        return self.page.evaluate(f"([path, argument]) => {{ const panel = {PANEL}; return {expression}; }}",
                                  [self.path, argument])

    def wait_until(self, condition: str, seconds: float) -> None:
        self.page.wait_for_function(f"path => {{ const panel = {PANEL}; return {condition}; }}", arg=self.path,
                                    timeout=seconds * 1000)

    def screenshot(self, step: str, what) -> None:
        """`what` (a cell or an output) scrolled into view: the page as the student sees it, and `what` alone."""
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        what.scroll_into_view_if_needed()
        self.page.screenshot(path=str(ARTIFACTS / f"{self.name}-{step}-page.png"))
        what.screenshot(path=str(ARTIFACTS / f"{self.name}-{step}.png"))

    def run_all(self) -> None:
        """Run > Run All Cells, and wait until the kernel has run them all."""
        self.evaluate("(window.jupyterapp.shell.activateById(panel.id), "
                      "window.jupyterapp.commands.execute('notebook:run-all-cells'))")
        self.wait_until("panel.sessionContext.session?.kernel?.status === 'idle' && panel.content.widgets.every("
                        "c => c.model.type !== 'code' || c.model.executionCount !== null)", RUN_ALL_S)

    def cell(self, tag: str):
        """The cell tagged `tag` (firmware, check) in the page."""
        index = self.evaluate("panel.content.widgets.findIndex(c => (c.model.getMetadata('tags') || [])"
                              ".includes(argument))", tag)
        assert index >= 0, f"{self.name} has no cell tagged {tag}"
        return self.page.locator(".jp-Notebook .jp-Cell").nth(index)

    def output_of(self, code: str):
        """The output of the code cell whose text has `code`."""
        return self.page.locator(".jp-Notebook .jp-CodeCell", has_text=code).locator(".jp-OutputArea")

    def run_cell_output(self):
        """The output of the cell that makes the station (`station = Station(...)`)."""
        return self.page.locator(".jp-Notebook .jp-CodeCell", has_text="station = Station(").locator(
            ".jp-OutputArea")

    def errors(self) -> list[str]:
        """The error outputs (tracebacks) in the notebook, as the kernel sent them."""
        return self.evaluate("panel.content.widgets.flatMap(c => c.model.type === 'code' ? "
                             "c.model.outputs.toJSON() : []).filter(o => o.output_type === 'error')"
                             ".map(o => o.ename + ': ' + o.evalue)")

    def replace_line(self, tag: str, old: str, new: str) -> None:
        """Click on the line that starts with `old` in the cell's editor, select it and type `new` over it."""
        line = self.cell(tag).locator(".cm-content .cm-line", has_text=old).first
        line.scroll_into_view_if_needed()
        line.click()
        self.page.keyboard.press("End")
        self.page.keyboard.press("Shift+Home")
        self.page.keyboard.type(new)
        self.page.keyboard.press("Escape")          # leave the editor, as a student clicking elsewhere does


@pytest.fixture
def page(browser):
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    context.set_default_timeout(PAGE_S * 1000)
    yield context.new_page()
    context.close()


def test_ex1_from_the_starter_to_full_marks_then_the_potentiometer(lab, page):
    notebook = Notebook(page, lab, "ex1")
    notebook.run_all()
    check = notebook.cell("check").locator(".jp-OutputArea")
    notebook.screenshot("1-starter-check", check)
    assert "EX1: 3/5" in check.inner_text()
    assert "RXB0 never received a frame" in check.inner_text() and "Set RX_Filter0" in check.inner_text()
    assert notebook.errors() == []

    notebook.replace_line("firmware", "MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x088     # the filter's ID: fix (c)")
    assert "MESSAGE_ID1 = 0x088" in notebook.cell("firmware").locator(".cm-content").inner_text()
    notebook.run_all()
    notebook.screenshot("2-fixed-check", check)
    assert "EX1: 5/5" in check.inner_text() and "FAIL" not in check.inner_text()
    board = notebook.run_cell_output()
    assert board.locator("img[alt*='line 4: RX ID  0x088']").count() == 1, "the LCD, drawn once"

    readout = board.locator(".widget-slider", has_text="your potentiometer").locator(".widget-readout")
    readout.click()
    page.keyboard.press("Control+a")
    page.keyboard.type("1000")
    page.keyboard.press("Enter")
    board.locator("img[alt*='line 3: A/D    1000']").wait_for()
    notebook.screenshot("3-potentiometer-board", board)


def test_ex3_with_a_typo_the_board_says_why_and_the_check_still_runs(lab, page):
    notebook = Notebook(page, lab, "ex3_typo")
    notebook.run_all()
    notebook.screenshot("1-board", notebook.run_cell_output())
    notebook.screenshot("2-check", notebook.cell("check"))
    board = notebook.run_cell_output().inner_text()
    line = 1 + next(n for n, text in enumerate((lab.root / "ex3.py").read_text().splitlines(), 1)
                    if "CANSetFliter" in text)
    said = (f"main() crashed at line {line} of the firmware cell (`CANSetFliter(CAN_FILTER_B1_F1, RX_Filter0, "
            "CAN_CONFIG_STD_MSG)`): NameError: name 'CANSetFliter' is not defined. Did you mean: 'CANSetFilter'?")
    assert "stopped. The check will say:" in board and said in board
    assert "Traceback" not in board and "classroom.py" not in board
    assert notebook.errors() == [], "no cell failed: Run All went on to the check"
    check = notebook.cell("check").locator(".jp-OutputArea").inner_text()
    assert "EX3: 0/5" in check and said in check


def test_00_its_pictures_and_the_prediction_typed_into_its_try(lab, page):
    notebook = Notebook(page, lab, "00_can_in_15_minutes")
    notebook.run_all()
    assert notebook.errors() == []
    for step, code in (("1-error-states", "plots.error_states()"), ("2-comstat", 'plots.register_bits("COMSTAT"'),
                       ("3-overload", "plots.recorded_wire(")):
        picture = notebook.output_of(code)
        assert picture.locator("img").count() == 1, f"{code} draws one picture"
        notebook.screenshot(step, picture)
    verdict = notebook.cell("try-check").locator(".jp-OutputArea")
    notebook.screenshot("4-try-as-shipped", verdict)
    assert "Your prediction: 1/5" in verdict.inner_text() and "TEC 15" not in verdict.inner_text()
    for board, counters in (("station1", "(15, 0)"), ("master", "(0, 1)"), ("third", "(0, 1)")):
        notebook.replace_line("try", f'"{board}": (None, None),', f'    "{board}": {counters},')
    notebook.run_all()
    notebook.screenshot("5-try-predicted", verdict)
    assert "Your prediction: 5/5" in verdict.inner_text() and "FAIL" not in verdict.inner_text()


def test_01_brgcon2_bit_by_bit_and_a_bit_timing_typed_into_its_try(lab, page):
    notebook = Notebook(page, lab, "01_bit_timing")
    notebook.run_all()
    assert notebook.errors() == []
    picture = notebook.output_of('plots.register_bits("BRGCON2"')
    assert picture.locator("img").count() == 1
    notebook.screenshot("1-brgcon2", picture)
    verdict = notebook.cell("try-check").locator(".jp-OutputArea")
    timeline = notebook.output_of("plots.bus_timeline(tried.bus.trace")
    notebook.screenshot("2-try-as-shipped", verdict)
    notebook.screenshot("3-bus-as-shipped", timeline)
    assert "Your bit timing: 1/4" in verdict.inner_text() and "125 kbit/s, not 250" in verdict.inner_text()
    for register, value in (("BRGCON1", "0xC3"), ("BRGCON2", "0xBE"), ("BRGCON3", "0x03")):
        notebook.replace_line("try", f"{register} = ", f"{register} = {value}      # 250 kbit/s: BRP 4, 1+7+8+4 TQ")
    notebook.run_all()
    notebook.screenshot("4-try-joins", verdict)
    notebook.screenshot("5-bus-joins", timeline)
    assert "Your bit timing: 4/4" in verdict.inner_text() and "FAIL" not in verdict.inner_text()
