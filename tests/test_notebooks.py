"""The notebooks run top to bottom in a real Jupyter kernel with the solutions in place, and ship with the starters."""
from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

KIT = Path(__file__).resolve().parent.parent
NOTEBOOKS = KIT / "notebooks"
ALL = sorted(path.stem for path in NOTEBOOKS.glob("*.ipynb"))
EXERCISES = {"ex1": "ex1", "ex2": "ex2", "ex3": "ex3", "ex4": "ex4", "ex5": "ex5", "ex6": "ex6",
             "demo1_monitor": "demo1"}
CELL_TIMEOUT_S = 120                 # a cell takes under a second; a hang fails fast
SCORE = re.compile(r"(\d+)/(\d+)")


def read(name: str) -> nbformat.NotebookNode:
    return nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)


def tagged(notebook: nbformat.NotebookNode, tag: str) -> list[nbformat.NotebookNode]:
    return [cell for cell in notebook.cells if tag in cell.metadata.get("tags", [])]


def firmware_file(cell: nbformat.NotebookNode) -> tuple[str, str]:
    """The file a firmware cell writes and the firmware in it (the cell's body below %%writefile)."""
    first, _, body = cell.source.partition("\n")
    magic, _, filename = first.partition(" ")
    assert magic == "%%writefile", "the firmware cell starts with %%writefile <file>"
    return filename, body


def test_every_workshop_notebook_is_there():
    assert set(ALL) == {"00_can_in_15_minutes", "01_bit_timing", *EXERCISES}


@pytest.mark.parametrize("name", sorted(EXERCISES))
def test_shipped_exercise_notebook_has_the_starter_in_its_firmware_cell_and_the_check(name):
    notebook = read(name)
    exercise = EXERCISES[name]
    assert notebook.metadata["appsim"] == {"exercise": exercise}
    [cell] = tagged(notebook, "firmware")
    filename, body = firmware_file(cell)
    assert filename == f"{name}.py"
    assert body == (KIT / "exercises" / filename).read_text(), "the student starts from exercises/" + filename
    [c_cell] = tagged(notebook, "firmware-c")
    c_file, c_body = firmware_file(c_cell)
    assert c_file == f"{name}.c" and c_body == (KIT / "exercises" / c_file).read_text(), "and in C from exercises/"
    [choice] = tagged(notebook, "firmware-choice")
    assert choice.source == f'FIRMWARE = "{filename}"', "the Python cell runs unless the student chooses the C one"
    [check_cell] = tagged(notebook, "check")
    assert check_cell.source == f'check("{exercise}", FIRMWARE)'
    assert not any(cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code"), \
        "notebooks ship without outputs"


def execute(name: str, workdir: Path, tries: dict[str, str] | None = None,
            language: str = "python") -> nbformat.NotebookNode:
    """Run a copy of the notebook in `workdir`, with the solutions in its firmware cells (and `tries`' source in
    the cell tagged with its key), the cells below running the one in `language`; fail on any cell error."""
    notebook = read(name)
    for cell in tagged(notebook, "firmware") + tagged(notebook, "firmware-c"):
        filename, _ = firmware_file(cell)
        cell.source = f"%%writefile {filename}\n" + (KIT / "solutions" / filename).read_text()
    for tag, source in (tries or {}).items():
        [cell] = tagged(notebook, tag)
        cell.source = source
    if language == "c":
        for cell in tagged(notebook, "firmware-choice"):
            cell.source = cell.source.replace('.py"', '.c"')
    client = NotebookClient(notebook, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                            resources={"metadata": {"path": str(workdir)}})
    try:
        client.execute()
    except CellExecutionError as error:
        pytest.fail(f"{name}.ipynb: a cell failed:\n{error}")
    return notebook


@pytest.mark.parametrize("name", ALL)
def test_notebook_runs_top_to_bottom_with_the_solutions_and_the_check_gives_full_marks(name, tmp_path):
    notebook = execute(name, tmp_path)
    errors = [output for cell in notebook.cells for output in cell.get("outputs", [])
              if output.output_type == "error"]
    assert not errors
    for cell in tagged(notebook, "firmware"):
        filename, body = firmware_file(cell)
        assert (tmp_path / filename).read_text() == body, "%%writefile wrote the cell's firmware next to the notebook"
    for cell in tagged(notebook, "check"):
        [result] = [output for output in cell.outputs if output.output_type == "execute_result"]
        shown = result.data["text/html"]
        scored, out_of = map(int, SCORE.search(shown).groups())
        assert out_of > 0 and scored == out_of, f"{name}: the solution should get full marks:\n{shown}"
        assert "FAIL" not in shown


RIGHT_ANSWERS = {
    "00_can_in_15_minutes": 'node, kind, bit, frames = "station1", "bit", 20, 2\n'
                            'prediction = {"station1": (15, 0), "master": (0, 1), "third": (0, 1)}',
    "01_bit_timing": "BRGCON1, BRGCON2, BRGCON3 = 0xC3, 0xBE, 0x03      # 250 kbit/s: BRP 4, 1 + 7 + 8 + 4 TQ",
}
"""A right answer to the try that ends notebooks 00 and 01: a prediction of the counters, a bit timing."""


@pytest.mark.parametrize("name", sorted(RIGHT_ANSWERS))
def test_the_try_that_ends_00_and_01_gives_full_marks_to_a_right_answer_in_a_real_kernel(name, tmp_path):
    notebook = read(name)
    assert [tag for cell in notebook.cells for tag in cell.metadata.get("tags", [])] == ["try", "try-check"]
    notebook = execute(name, tmp_path, {"try": RIGHT_ANSWERS[name]})
    [cell] = tagged(notebook, "try-check")
    [result] = [output for output in cell.outputs if output.output_type == "execute_result"]
    shown = result.data["text/html"]
    scored, out_of = map(int, SCORE.search(shown).groups())
    assert out_of >= 4 and scored == out_of and "FAIL" not in shown, shown


@pytest.mark.parametrize("name", sorted(EXERCISES))
def test_an_exercise_notebook_runs_the_c_cell_when_chosen_and_its_check_judges_the_c(name, tmp_path):
    notebook = execute(name, tmp_path, language="c")
    assert not [output for cell in notebook.cells for output in cell.get("outputs", [])
                if output.output_type == "error"]
    [cell] = tagged(notebook, "check")
    [result] = [output for output in cell.outputs if output.output_type == "execute_result"]
    shown = result.data["text/html"]
    scored, out_of = map(int, SCORE.search(shown).groups())
    assert out_of > 0 and scored == out_of, f"{name} in C: the solution should get full marks:\n{shown}"
    assert f"{name}.c" in shown and f"{name}.py ran" not in shown


def test_a_c_firmware_cell_s_errors_name_its_line_in_the_cell(tmp_path):
    notebook = read("ex1")
    [cell] = tagged(notebook, "firmware-c")
    cell.source = cell.source.replace("CANSetOperationMode(CAN_OP_MODE_LOOP);", "CANSetOperationMode(CAN_OP_MODE_LOOP)")
    line = next(n for n, text in enumerate(cell.source.splitlines(), 1) if "CAN_OP_MODE_LOOP)" in text) + 1
    for choice in tagged(notebook, "firmware-choice"):
        choice.source = 'FIRMWARE = "ex1.c"'
    client = NotebookClient(notebook, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    [check] = tagged(notebook, "check")
    shown = check.outputs[0].data["text/plain"]
    assert f"the C firmware cell:{line}:" in shown and "is a ';' missing" in shown, shown
    assert not [o for c in notebook.cells for o in c.get("outputs", []) if o.output_type == "error"]
