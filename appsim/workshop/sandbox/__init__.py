"""The grader's sandbox: each student firmware in its own sandboxed process, the board and the checks in the grader.

`isolation.isolation()` gives the operating system's walls (or says why this machine has none); `host.Sandbox` starts
children; `host.SandboxedFirmware` is a firmware file for `check()`, run in one of them; `child` is what runs inside.
This package's modules import no more than they need: the child imports only `protocol` and the firmware library.
"""
