"""The agents benchmark's bookkeeping (issue 17): its targets, the rows it runs, and the
checkpoints the active-localization comparison uses (no env is built here)."""

from __future__ import annotations

import pytest

from localization.workflows.benchmarks.agents import (
    TARGET_RATIO,
    AgentsBenchConfig,
    _rows,
    _targets,
    comparison_policies,
)


def _row(name: str, success: float, episodes: int = 200) -> dict:
    return {"row": name, "success_rate": success, "episodes": episodes}


def test_targets_compare_belief_with_true_pose_success_and_training_minutes():
    training = {"oracle": {"train_seconds": 600.0}, "belief": {"train_seconds": 2400.0}}
    targets = {t[0]: t for t in _targets([_row("PPO, true pose", 1.0),
                                         _row("PPO, belief", TARGET_RATIO)], training)}
    assert targets["PPO success, belief / true pose"][3]
    assert targets["held-out episodes per row"][3]
    assert targets["PPO training time, oracle (min)"][3]
    assert not targets["PPO training time, belief (min)"][3]  # 40 min > 30
    low = _targets([_row("PPO, true pose", 1.0), _row("PPO, belief", 0.9, 100)], training)
    assert not low[0][3] and not low[1][3]


def test_rows_have_the_comparison_only_with_an_active_policy(tmp_path):
    policies = {"oracle": "o.pt", "belief": "b.pt"}
    assert [r[0] for r in _rows(AgentsBenchConfig(), policies)] == ["PPO, true pose",
                                                                    "PPO, belief"]
    args = AgentsBenchConfig(active_penalty=0.01, active_episodes=7)
    rows = _rows(args, {**policies, "active": "a.pt"})
    assert [r[0] for r in rows[2:]] == ["plain, kidnap", "active (0.01), kidnap",
                                        "plain, night", "active (0.01), night"]
    assert rows[2][2] == {"agent": "b.pt", "kidnap_at": (args.kidnap_step,)}
    assert rows[4][2] == {"agent": "b.pt", "conditions": "night"} and rows[4][3] == 7


def test_a_shorter_active_run_is_compared_at_the_same_checkpoint(tmp_path):
    policies = {}
    for name in ("belief", "active"):
        folder = tmp_path / name
        (folder / "checkpoints").mkdir(parents=True)
        (folder / "checkpoints" / "policy_100000.pt").write_bytes(b"")
        policies[name] = str(folder / "policy.pt")
    same = AgentsBenchConfig(active_penalty=0.01)
    assert comparison_policies(same, policies) == policies
    short = AgentsBenchConfig(active_penalty=0.01, active_timesteps=100_000)
    chosen = comparison_policies(short, policies)
    assert chosen["belief"].endswith("belief/checkpoints/policy_100000.pt")
    assert chosen["active"].endswith("active/checkpoints/policy_100000.pt")
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        comparison_policies(AgentsBenchConfig(active_timesteps=200_000), policies)
