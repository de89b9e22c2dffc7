"""What train/pasta.py logs per update: where the time goes (collection against the learner)."""

from types import SimpleNamespace

import numpy as np

from sofar_agents.pasta.training_log import console_line, log_update


class RecordingWriter:
    def __init__(self):
        self.scalars = {}

    def add_scalar(self, tag, value, step):
        self.scalars[tag] = (float(value), step)

    def add_histogram(self, tag, values, step):
        pass


def _stats(collect_time=2.0, update_time=1.0):
    names = 2
    return {"policy_loss": 0.1, "value_loss": 0.2, "entropy": 0.3, "approx_kl": 0.01, "clipfrac": 0.1,
            "log_std": -1.0, "mu": 5.0, "conflict_ratio": 0.4, "sps": 1000.0, "epochs": 4,
            "attention": np.full(names, 0.5), "regret": np.zeros(names), "return_scale": np.ones(names),
            "explained_variance": np.full(names, 0.5), "episodes": [], "update_time": update_time,
            "collect_time": collect_time,
            "rollout": SimpleNamespace(rewards=np.zeros((512, 4, names)), actions=np.full((512, 4, 1), 0.3))}


def _agent():
    return SimpleNamespace(num_timesteps=2048, num_updates=1, objective_names=("safety", "overtakes"),
                           preference=np.array([0.5, 0.5]), ep_info_buffer=[])


def test_the_collection_rate_and_the_update_time_are_logged():
    writer = RecordingWriter()
    log_update(writer, _agent(), _stats(collect_time=2.0, update_time=1.5))
    assert writer.scalars["charts/collect_sps"] == (512 * 4 / 2.0, 2048)
    assert writer.scalars["time/collect_s"][0] == 2.0
    assert writer.scalars["time/update_s"][0] == 1.5
    line = console_line(_agent(), _stats(collect_time=2.0, update_time=1.5), 8192)
    assert line.endswith("sps 1000 (collection 2.0 s, update 1.5 s)")


def test_without_a_collection_time_only_the_update_time_is_logged():
    stats = _stats()
    del stats["collect_time"]
    writer = RecordingWriter()
    log_update(writer, _agent(), stats)
    assert "charts/collect_sps" not in writer.scalars and "time/update_s" in writer.scalars
    assert console_line(_agent(), stats, 8192).endswith("sps 1000")


def test_resuming_a_run_in_its_own_folder_needs_no_force(tmp_path):
    """``--resume`` into the run's own folder is the normal case; ``--force`` is for starting over."""
    import json

    import pytest

    from sofar_agents.pasta.training_log import check_out, run_folder

    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    final = out / "pasta_final.json"
    final.write_text(json.dumps({"state": {"num_timesteps": 256}}))
    assert run_folder(final) == out.resolve()
    assert run_folder(out / "checkpoints" / "pasta_0000000128.json") == out.resolve()
    check_out(out, force=False, resume=final)  # its own run
    check_out(out, force=False, resume=out / "checkpoints" / "pasta_0000000128.json")
    check_out(out, force=True)  # starting over
    check_out(tmp_path / "empty", force=False)  # nothing there
    for resume in (None, tmp_path / "other" / "pasta_final.json"):
        with pytest.raises(SystemExit) as refused:
            check_out(out, force=False, resume=resume)
        message = str(refused.value)
        assert "256 steps" in message and f"--resume {final}" in message and "--force" in message
        assert "overwrite" not in message
