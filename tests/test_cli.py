"""The command lines' shared parsing (`arld_jax.cli`), the import graph around it, and every help
text as a person reads it."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from arld_jax import cli, config, run
from arld_jax.config import STRATEGIES
from arld_jax.human import cli as human_cli
from arld_jax.human.cli import human_config
from arld_jax.sweep import SWEEP_PRESETS

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "arld_jax"

LEAK = re.compile(r"\{'option_strings'|%\(|%%|%[-#0 +]*\d*(?:\.\d+)?[sdrifgex]\b")
"""What argparse leaves in a help text it could not format: its own action dict (a bare "%" that
ate the argument), "%(" and "%%" (a placeholder or an escape it did not expand), "%s", "%5.1f"..."""


def leaks(text: str) -> list[str]:
    return LEAK.findall(text)


def help_of(capsys: pytest.CaptureFixture[str], call, *args) -> str:  # noqa: ANN001
    """What `call(*args)` prints for --help (it must exit with status 0)."""
    with pytest.raises(SystemExit) as exit_info:
        call(*args)
    assert exit_info.value.code == 0
    out = capsys.readouterr()
    assert out.err == ""
    return out.out


# ---------------------------------------------------------------- help texts


def test_leak_pattern_catches_argparse_failures_and_passes_a_percent_sign():
    # A help string holding "95% s..." once printed argparse's action dict in its place.
    broken = "P(a > b) with 95{'option_strings': [], 'dest': 'compare'}tratified-bootstrap CIs"
    assert leaks(broken) and leaks("at %(default)s") and leaks("100%% sure") and leaks("x %s")
    assert leaks("%5.1f") and leaks("%d steps")
    assert not leaks("with 95% stratified-bootstrap CIs; 12% of states, 100 %")


def test_top_level_help_lists_every_command_with_its_line(capsys):
    text = help_of(capsys, run.main, ["--help"])
    assert not leaks(text), leaks(text)
    flat = " ".join(text.split())
    assert set(run.COMMANDS) == {
        "seed_sweep",
        "train_expert",
        "demonstrate",
        "plot",
        "summary",
        "compare",
        "export_expert",
        "evaluate_expert",
    }
    for name, summary in run.COMMANDS.items():
        assert re.search(rf"^\s+{name}\b", text, re.MULTILINE), name
        assert " ".join(summary.split()) in flat, name
    assert "95% stratified-bootstrap CIs" in flat


@pytest.mark.parametrize("command", list(run.COMMANDS))
def test_every_command_help_renders(capsys, command):
    text = help_of(capsys, run.main, [command, "--help"])
    assert text.startswith(f"usage: python -m arld_jax.run {command} ")
    assert not leaks(text), leaks(text)
    assert "(default: None)" not in text  # an option not given is explained by its help
    first_line = cli.sentence(run.COMMANDS[command])
    assert " ".join(first_line.split()) in " ".join(text.split())


def test_human_help_and_clone_help_render(capsys):
    for argv in ([], ["clone"]):
        text = help_of(capsys, human_cli.main, [*argv, "--help"])
        assert text.startswith(" ".join(["usage: python -m arld_jax.human", *argv]))
        assert not leaks(text), leaks(text)


def test_demonstrate_lists_the_parser_it_is_run_with(capsys):
    """run.py's `demonstrate` entry and the parser its arguments are handed to are one."""
    listed = help_of(capsys, run.parse_args, ["demonstrate", "--help"])
    used = help_of(capsys, run.main, ["demonstrate", "--help"])
    assert listed == used
    assert "clone RUN_DIR_OR_DATASET --out EXPERT_DIR" in used


def test_training_help_lists_each_field_once_with_its_docstring(capsys):
    text = help_of(capsys, run.main, ["seed_sweep", "--help"])
    docs = config.field_docs()
    for name in cli.FIELDS:
        assert len(re.findall(rf"^\s+--{name}\b", text, re.MULTILINE)) == 1, name
    flat = " ".join(text.split())
    assert docs["t_query"] in flat and "[sweepable] (Config default: 0.1)" in flat
    human = " ".join(help_of(capsys, human_cli.main, ["--help"]).split())
    assert "[sweepable]" not in human and "config fields (one value each)" in human


def test_pruning_rule_is_read_from_the_sweep():
    assert cli.pruning_rule() == (
        "query_prob outside bernoulli, t_query outside active, demo_steps/budget/eps_demo under none"
    )


# ---------------------------------------------------------------- imports


def _fresh_modules(statement: str) -> set[str]:
    code = f"import sys; {statement}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    return set(out.stdout.split())


def test_dataset_and_session_load_without_jax():
    modules = _fresh_modules("import arld_jax.human.dataset, arld_jax.human.session")
    assert "arld_jax.human.dataset" in modules
    assert "jax" not in modules and "arld_jax.human.cli" not in modules


def test_cli_is_a_leaf_and_human_cli_stands_without_run():
    leaf = _fresh_modules("import arld_jax.cli")
    assert "arld_jax.cli" in leaf
    assert not {m for m in leaf if m == "arld_jax.run" or m.startswith("arld_jax.human")}
    human = _fresh_modules("import arld_jax.human.cli")
    assert "arld_jax.cli" in human and "arld_jax.run" not in human


def _imported(path: Path) -> set[str]:
    """Every module `path` imports, at any depth of its code (function-local ones too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
    return names


def test_no_import_circle_through_run_or_the_shared_parser():
    """cli.py imports neither command line; no module of arld_jax.human imports run.py, and only
    `python -m arld_jax.human`'s __main__ imports human/cli.py (at any depth of their code)."""
    forbidden = ("arld_jax.run", "arld_jax.human")
    assert not {m for m in _imported(PACKAGE / "cli.py") if m.startswith(forbidden)}
    human = sorted((PACKAGE / "human").glob("*.py"))
    assert not [p.name for p in human if "arld_jax.run" in _imported(p)]
    importers = {p.name for p in human if "arld_jax.human.cli" in _imported(p)}
    assert importers == {"__main__.py"}


# ---------------------------------------------------------------- the person's command line


def test_human_preset_and_overrides():
    _, cfg = human_cli.parse_args([])
    assert cfg == human_config()
    _, cfg = human_cli.parse_args(["--budget", "40", "--strategy", "bernoulli"])
    assert (cfg.budget, cfg.strategy) == (40, "bernoulli")
    # A sweep preset is demonstrated with the active strategy unless --strategy says otherwise.
    _, cfg = human_cli.parse_args(["--preset", "sac"])
    assert (
        cfg.strategy == "active"
        and cfg.total_env_steps == SWEEP_PRESETS["sac"]().cfg.total_env_steps
    )


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--t_query", "0.1,0.2"], "give one value for t_query"),
        (["--agent", "sac,td3"], "give one value for --agent"),
        (["--preset", "fig1"], "one program per agent"),
        (["--strategy", "none"], "never asks the person; use greedy, bernoulli, active"),
        (["--budget", "lots"], "--budget 'lots' is not a valid int"),
    ],
)
def test_human_command_line_refuses_what_one_person_cannot_demonstrate(argv, message):
    with pytest.raises(SystemExit, match=re.escape(message)):
        human_cli.parse_args(argv)


@pytest.mark.parametrize(
    ("prog", "parse"),
    [
        ("python -m arld_jax.human", human_cli.parse_args),
        ("python -m arld_jax.run seed_sweep", lambda a: run.parse_args(["seed_sweep", *a])),
    ],
)
def test_unknown_option_names_its_close_matches_in_both_command_lines(capsys, prog, parse):
    with pytest.raises(SystemExit) as exit_info:
        parse(["--t_qury", "0.1", "--chunk_perods=2", "--no_plots", "stray"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: {prog}")  # the command's own usage, not the top level's
    assert "unknown option --t_qury (did you mean --t_query" in err
    assert "unknown option --chunk_perods (did you mean --chunk_periods?)" in err
    assert "unexpected argument 'stray'" in err
    assert "'0.1'" not in err  # the value of an unknown option is not a second complaint


def test_run_options_come_from_the_shared_options():
    args, _ = run.parse_args(
        ["seed_sweep", "--preset", "tiny", "--chunk_periods", "2", "--stop_after_chunks", "1"]
        + ["--no_plots"]
    )
    options = cli.run_options(args, command="python -m arld_jax.run x", preset=args.preset)
    assert (options.chunk_periods, options.stop_after_chunks, options.plots) == (2, 1, False)
    assert (options.command, options.preset, options.log) == (
        "python -m arld_jax.run x",
        "tiny",
        cli.log,
    )
    args, _ = human_cli.parse_args(["--chunk_periods", "4"])
    options = cli.run_options(args, command="c", preset=args.preset)
    assert (options.chunk_periods, options.stop_after_chunks, options.plots) == (4, None, True)
    assert options.preset == "human"


def test_train_expert_defaults_to_the_sac_preset():
    args, sweep = run.parse_args(["train_expert"])
    assert args.preset == "expert"
    assert sweep.to_json() == SWEEP_PRESETS["sac"]().to_json()


def test_task_presets_run_on_any_task():
    """`sac_300k` and `arld_task` take the task from --env_name: plain SAC at 300k over 5 seeds,
    and the four strategies with sigma_theta at the `arld` protocol, on the C engine on a CPU."""
    _, sac = run.parse_args(["seed_sweep", "--preset", "sac_300k", "--env_name", "walker2d"])
    assert (sac.cfg.env_name, sac.cfg.total_env_steps, sac.cfg.strategy) == (
        "walker2d",
        300_000,
        "none",
    )
    assert sac.seeds == (0, 1, 2, 3, 4) and sac.sweep == {}
    _, arld = run.parse_args(["seed_sweep", "--preset", "arld_task", "--env_name", "hopper"])
    assert arld.cfg.env_name == "hopper" and arld.sweep == {"strategy": STRATEGIES}
    assert (arld.cfg.total_env_steps, arld.cfg.budget, arld.cfg.demo_steps) == (100_000, 2_500, 1)
    assert arld.cfg.uncertainty == "intrinsic"
    assert arld.cfg.backend == config.auto_backend(config.jax_platform())


def test_env_steps_benchmark_reads_physics_settings_and_refuses_bad_ones(capsys, tmp_path):
    from benchmarks import env_steps

    assert env_steps.parse_solvers("default,100/50") == [
        {},
        {"solver_iterations": 100, "solver_ls_iterations": 50},
    ]
    for bad in ("100", "0/5", "100/50/1", "a/b", "", "100/-1"):
        with pytest.raises(ValueError, match=f"got {bad!r}; allowed: 'default'"):
            env_steps.parse_solvers(bad)
    out = tmp_path / "report.json"
    for argv, named in (
        (["--tasks", "ant", "--solvers", "default,1/"], "--solvers: got '1/'"),
        (["--tasks", "toy", "--solvers", "100/50"], "Config.solver_iterations = 100"),
        (["--tasks", "ant", "--contacts", "task,every"], "Config.contacts = 'every' is invalid"),
        (["--tasks", "ant", "--integrators", "rk4,euler"], "Config.integrator = 'euler'"),
        (["--tasks", "toy", "--integrators", "rk4"], "Config.integrator = 'rk4' is invalid"),
    ):
        with pytest.raises(SystemExit) as exit_:  # refused before anything compiles or is written
            env_steps.main([*argv, "--backends", "mujoco", "--out", str(out)])
        assert exit_.value.code == 2 and named in capsys.readouterr().err
        assert not out.exists()
