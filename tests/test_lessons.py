"""What the lessons teach agrees with the checks: where the workshop, the data sheet and the CAN standard differ, the
check accepts what each of them allows, and says why when it refuses."""
from __future__ import annotations

import pytest

from appsim.workshop.checks import check
from appsim.workshop.course import solution

RTR_LINE = "CANSendMessage(RTR_ID, None, 0,"


@pytest.mark.parametrize("dlc, passes", [(0, True), (5, True), (3, False), (8, False)])
def test_an_ex5_request_may_have_the_workshops_dlc_0_or_the_standards_5(tmp_path, dlc, passes):
    source = solution("ex5").read_text()
    assert source.count(RTR_LINE) == 1
    firmware = tmp_path / "ex5.py"
    firmware.write_text(source.replace(RTR_LINE, f"CANSendMessage(RTR_ID, None, {dlc},"))
    verdict = check("ex5", firmware, seed=11)
    requests = verdict.checks[1]
    assert requests.passed is passes, str(verdict)
    assert verdict.passed is passes
    if passes:
        assert f"RTR DLC {dlc}" in requests.message
    else:
        for words in (f"RTR DLC {dlc}", "The workshop sends DataLen 0", "CAN 2.0 advises", "5 here", "bit error"):
            assert words in requests.message, requests.message
