"""The grader's sandbox: each submission's firmware in a sandbox of its own, a fresh process for each exercise, the
board and the checks in the grader.

`isolation.isolation()` gives the operating system's walls (or says why this machine has none); `children.Sandbox`
boots a sandbox per submission and takes a process from it per exercise; `host.SandboxedFirmware` is a firmware file for
`check()`, run in one of them; `zygote` is what boots inside and forks, `child` what each forked process runs.
This package's modules import no more than they need: inside, only `protocol` and the firmware library.
"""
