"""The contextrl command: list, describe, docs and render read the feature declarations."""

import pytest
from PIL import Image

import contextrl as crl
from contextrl.cli import main, parse_assignments, parse_grid
from tests.helpers import ROOT

pytestmark = pytest.mark.quick


def test_list_shows_every_environment_with_its_counts(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for env_id in crl.registered():
        assert env_id in out
    cartpole = next(line for line in out.splitlines() if line.startswith("CartPole "))
    # id, family, kind, action, obs size, features, dynamics, reward, max_steps
    assert cartpole.split() == [
        "CartPole",
        "classic_control",
        "jax",
        "Discrete(2)",
        "4",
        "8",
        "6",
        "0",
        "500",
    ]


def test_describe_prints_the_feature_table(capsys):
    assert main(["describe", "CARLCartPole"]) == 0
    out = capsys.readouterr().out
    length = next(line for line in out.splitlines() if line.startswith("length "))
    for text in ("0.5", "[0.05, 5]", "m", "dynamics", "half the pole's length", "pole_length"):
        assert text in length
    assert main(["describe", "Pendulum", "--markdown"]) == 0
    assert "| g | 10 |" in capsys.readouterr().out


def test_describe_lists_the_features_that_act_in_a_brax_pipeline(capsys):
    """Hopper's masses cannot act on brax's spring pipeline (its model fixes the effective masses)."""
    pytest.importorskip("brax")
    assert main(["describe", "BraxHopper"]) == 0
    assert "mass_torso" in capsys.readouterr().out
    assert main(["describe", "BraxHopper", "--backend", "spring"]) == 0
    out = capsys.readouterr().out
    assert "mass_" not in out and "elasticity" in out


def test_docs_are_generated_from_the_declarations(tmp_path, capsys):
    out = tmp_path / "env.md"
    assert main(["docs", "--out", str(out)]) == 0
    text = out.read_text()
    for env_id in crl.registered():
        assert f"## {env_id}" in text and f"contextrl/{env_id}-v0" in text
    space = crl.make("Acrobot").context_space
    for name, feature in space.features.items():
        assert f"| {name} | {feature.default_label()} |" in text


def test_render_writes_a_grid_animation(tmp_path, capsys):
    out = tmp_path / "grid.gif"
    code = main(
        [
            "render",
            "CartPole",
            "--grid",
            "length=0.25,1.0",
            "--context",
            "gravity=5",
            "--steps",
            "4",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    with Image.open(out) as gif:
        assert gif.n_frames == 5
        assert gif.size[0] == 2 * 600 + 4


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["describe", "CartPol"], "Did you mean"),
        (
            ["describe", "CartPole", "--backend", "spring"],
            "only the Brax and dm_control environments",
        ),
        (["render", "CartPole", "--context", "length=9"], "outside its bounds"),
        (["render", "CartPole", "--context", "lenght=1"], "unknown context feature"),
        (["render", "CartPole", "--grid", "length"], "FEATURE=V1,V2"),
    ],
)
def test_user_errors_print_one_line_and_return_2(argv, message, capsys, tmp_path):
    assert main([*argv, *(["--out", str(tmp_path / "x.gif")] if argv[0] == "render" else [])]) == 2
    err = capsys.readouterr().err
    assert message in err and not list(tmp_path.iterdir())


def test_assignment_parsing():
    assert parse_assignments(["length=1.5", "gravity=5,tau=0.01"]) == {
        "length": 1.5,
        "gravity": 5.0,
        "tau": 0.01,
    }
    assert parse_grid("length=0.25, 0.5") == ("length", [0.25, 0.5])
    with pytest.raises(crl.ContextError):
        parse_assignments(["length"])


def test_the_environment_docs_and_index_are_up_to_date():
    """docs/environments.md and the index `contextrl list` reads are what the environments give."""
    import json

    from contextrl.cli import ENVIRONMENT_INDEX, environment_rows, environments_markdown

    rows = environment_rows(build=True)
    page = ROOT / "docs" / "environments.md"
    assert page.read_text() == environments_markdown(rows), (
        "docs/environments.md is stale: run `contextrl docs --out docs/environments.md`"
    )
    index = json.loads(ENVIRONMENT_INDEX.read_text(encoding="utf-8"))
    assert list(index.values()) == rows, "run tools/write_environment_index.py"
