"""The plant and tracking benchmarks stand below the experiments with no exception: the plant
variants, the fin rig and the scenario runner they run are the backend's, so an experiment
imported by either breaks the layers."""

from __future__ import annotations

from pathlib import Path

from test_layers import _copy_package, lint_imports


def test_the_plant_and_tracking_benchmarks_importing_an_experiment_fail(tmp_path: Path) -> None:
    _copy_package(tmp_path)
    for name in ("plant", "tracking"):
        path = tmp_path / "ucat_console" / "bench" / f"{name}.py"
        path.write_text(path.read_text() + "\n\ndef _leak():\n    from ucat_console.experiments import scenario\n")
    run = lint_imports(tmp_path)
    assert run.returncode != 0
    assert "ucat_console.bench.plant -> ucat_console.experiments.scenario" in run.stdout
    assert "ucat_console.bench.tracking -> ucat_console.experiments.scenario" in run.stdout
    assert "the tool packages in layers" in run.stdout and "1 broken" in run.stdout
