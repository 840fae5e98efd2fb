"""The build, as pyproject.toml configures it, plus one step: a wheel records the git commit it was built from
(appsim/COMMIT in the wheel, read by appsim.provenance), so an installed kit can say which commit it is."""
import importlib.util
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("provenance", HERE / "appsim" / "provenance.py")
assert _spec is not None and _spec.loader is not None
provenance = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(provenance)


class BuildPyRecordingTheCommit(build_py):
    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):            # an editable kit asks git itself, as it runs
            return
        commit = provenance.checkout_commit(HERE)
        recorded = Path(self.build_lib, "appsim", provenance.RECORDED)
        if commit is None:                                   # built from a copy that is no checkout: nothing to say
            recorded.unlink(missing_ok=True)
        else:
            recorded.write_text(commit + "\n", encoding="utf-8")


setup(cmdclass={"build_py": BuildPyRecordingTheCommit})
