"""A check of what a node leaves undone (it does not receive its own frames, rejects the others', stays silent unless
polled, is invisible) gives no point to a node that takes no part in the bus: doing nothing is no merit. A firmware
that only loops earned 13 of 35 points; now it earns the one point of each exercise's "firmware runs"."""
from __future__ import annotations

import pytest

from appsim.workshop.checks import check
from appsim.workshop.course import EXERCISES

DO_NOTHING = {
    "c": '#include <p18f8680.h>\n#include "CAN18XX8.h"\n#define MESSAGE_ID1 0x100\n'
         "void main(void) { while (1) { CANIsRxReady(); } }\n",
    "py": "from appsim.firmware import *\n\nMESSAGE_ID1 = 0x100\n\n\ndef main():\n    while True:\n"
          "        CANIsRxReady()\n",
}


@pytest.mark.parametrize("language", ["c", "py"])
@pytest.mark.parametrize("exercise", EXERCISES)
def test_a_firmware_that_does_nothing_gets_only_the_point_for_running(tmp_path, exercise, language):
    path = tmp_path / f"idle.{language}"
    path.write_text(DO_NOTHING[language])
    verdict = check(exercise, path, seed=1).to_dict()
    passed = [c["name"] for c in verdict["checks"] if c["passed"]]
    assert passed == ["firmware runs"] and verdict["score"] == 1, verdict


def test_a_node_that_is_on_the_bus_but_never_answers_is_not_silent_by_merit(tmp_path):
    """The Ex6 starter listens and ACKs but never answers a poll: silence is right only for a node that answers."""
    verdict = check("ex6", "exercises/ex6.c", seed=2).to_dict()
    silent = next(c for c in verdict["checks"] if c["name"] == "silent unless polled")
    assert not silent["passed"] and "Silence is right only for a node that answers when asked" in silent["message"]
