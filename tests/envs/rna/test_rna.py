"""RnaDesign on ViennaRNA: known solutions solve their targets, rewards match hand computations, every
context feature acts, bad data and ids are refused, and gymnasium's faces work."""

from __future__ import annotations

import importlib.resources
import itertools

import numpy as np
import pytest

from tests.helpers import ROOT

pytest.importorskip("RNA")

import gymnasium  # noqa: E402
import jax  # noqa: E402
import RNA  # noqa: E402

import contextrl  # noqa: E402, F401  (registers the gymnasium ids)
from contextrl.context.features import ContextError  # noqa: E402
from contextrl.envs.rna import (  # noqa: E402
    RnaDesign,
    SyntheticTargets,
    TargetError,
    TargetSets,
    fold,
    pair_table,
)
from contextrl.envs.rna import design as design_module  # noqa: E402
from contextrl.envs.rna.targets import count_multiloops  # noqa: E402
from tests.helpers import learning

HAIRPIN = "(((((......)))))"  # Eterna100 v2 target 1, "Simple Hairpin"
HAIRPIN_ONLY = {"target_id_first": 1, "target_id_last": 1}


@pytest.fixture(scope="module")
def env() -> RnaDesign:
    return RnaDesign()


def design(env: RnaDesign, actions, seed: int = 0, **context) -> tuple[float, dict]:
    """Run one episode with ``actions``: (final reward, final info)."""
    env.reset_physics(env.context(**context), np.random.default_rng(seed))
    rewards = []
    for action in actions:
        _, reward, terminated = env.step_physics(action)
        rewards.append(reward)
    assert terminated and all(r == 0.0 for r in rewards[:-1])
    return rewards[-1], env.step_info()


def actions_writing(env: RnaDesign, sequence: str, **context) -> list[int]:
    env.reset_physics(env.context(**context), np.random.default_rng(0))
    return env.actions_for(sequence)


def test_eterna100_v2_sample_solutions_solve_their_targets():
    env = RnaDesign(wobble_pairs=True)  # most sample solutions hold GU pairs
    solved = []
    for target_id in range(1, 101):
        target = env.targets.get("eterna100_v2", target_id)
        if target.solution is None:  # #100's solution is undisclosed
            continue
        ids = {"target_id_first": target_id, "target_id_last": target_id}
        actions = actions_writing(env, target.solution, **ids)
        reward, info = design(env, actions, **ids)
        assert info["sequence"] == target.solution and info["target_id"] == target_id
        if info["structure"] == target.structure:
            assert reward == 1.0 and info["hamming_distance"] == 0 and info["solved"]
            assert info["folds"] == 1  # solved by the design itself, no local improvement
            solved.append(target_id)
    assert len(solved) == 99 and 100 not in solved


def test_a_wrong_design_gets_the_hand_computed_reward(env):
    one = {"target_id_first": 1, "target_id_last": 1}
    actions = [0] * 5 + [0] * 6  # AU pairs, then A in the loop: AAAAAAAAAAAUUUUU folds to nothing
    reward, info = design(env, actions, **one)
    assert info["sequence"] == "AAAAAAAAAAAUUUUU" and info["structure"] == "." * 16
    assert info["hamming_distance"] == 10 and not info["solved"]  # the ten paired sites
    assert reward == pytest.approx(1 - 10 / 16)
    reward, _ = design(env, actions, reward_exponent=2.0, **one)
    assert reward == pytest.approx((1 - 10 / 16) ** 2)


PRION = {"target_id_first": 3, "target_id_last": 3}  # "((((((.((((....))))))).)))..........", 36 nt
PRION_DESIGNS = {  # Watson–Crick designs of Eterna100 v2 target 3, by the distance of their own fold
    4: "UCCAGGUUUUUAACCAAAACCUUGGAUCGGUACGCU",  # LEARNA's improvement solves it
    5: "GGAGAUUACGUGUUUACGUAUCUUCCCACCGCAGGC",  # LEARNA's improvement would reach 2
    6: "CGUUAAUUACUCCUCAGUAUUACACGGGAAUUUGUC",
}


def learna_reward(sequence: str, target: str, threshold: float, exponent: float) -> float:
    """LEARNA's terminal reward from its definition (Runge et al. 2019; automl/learna's
    environment.py): fold the design (ViennaRNA MFE) and take the Hamming distance d to the target;
    when 0 < d < threshold, d becomes the least distance over every A/C/G/U assignment to the sites
    where the fold differs (each site on its own); the reward is (1 − d/n)^exponent."""

    def distance(candidate: str) -> int:
        return sum(a != b for a, b in zip(RNA.fold(candidate)[0], target, strict=True))

    d = distance(sequence)
    if 0 < d < threshold:
        folded = RNA.fold(sequence)[0]
        wrong = [i for i in range(len(target)) if folded[i] != target[i]]
        for bases in itertools.product("ACGU", repeat=len(wrong)):
            mutated = list(sequence)
            for site, base in zip(wrong, bases, strict=True):
                mutated[site] = base
            d = min(d, distance("".join(mutated)))
    return (1 - d / len(target)) ** exponent


@pytest.mark.parametrize(
    "own_distance, threshold", [(4, 5.0), (5, 5.0), (6, 5.0), (5, 6.0), (4, 4.0)]
)
def test_reward_is_learnas_below_at_and_above_the_mutation_threshold(env, own_distance, threshold):
    """Designs whose own fold is at d = threshold − 1, threshold and threshold + 1 (LEARNA's default
    threshold 5 and two others): the reward equals LEARNA's, so improvement runs only when d is
    strictly below the threshold, and then exhausts every base at the mismatched sites."""
    sequence = PRION_DESIGNS[own_distance]
    target = env.targets.get("eterna100_v2", 3).structure
    assert sum(a != b for a, b in zip(fold(sequence), target, strict=True)) == own_distance
    actions = actions_writing(env, sequence, **PRION)
    reward, info = design(env, actions, mutation_threshold=threshold, **PRION)
    assert reward == pytest.approx(learna_reward(sequence, target, threshold, 1.0), abs=1e-12)
    improved = own_distance < threshold
    expected = {4: 0, 5: 2, 6: 6}[own_distance] if improved else own_distance
    assert info["hamming_distance"] == expected
    assert fold(info["sequence"]) == info["structure"]
    assert (info["sequence"] != sequence) == improved and (info["folds"] > 1) == improved
    if own_distance == 5 and improved:  # no design of distance < 2 among the 4^5 combinations
        assert info["folds"] == 4**5  # the design's own fold, then the 1,023 others


def test_actions_are_learnas_four_unless_wobble_pairs_are_asked_for():
    """LEARNA's 4 actions: a uniform policy places each base with probability 1/4 at an unpaired
    site and each Watson–Crick pair with 1/4 at a paired one; ``wobble_pairs`` adds GU and UG."""
    env = RnaDesign()
    assert env.action_space.n == 4
    for action, pair in enumerate(["AU", "CG", "GC", "UA"]):
        _, info = design(env, [action] * 11, mutation_threshold=0.0, **HAIRPIN_ONLY)
        assert (
            info["sequence"] == pair[0] * 5 + pair[0] * 6 + pair[1] * 5
        )  # hairpin: 5 pairs, 6 loop
    env.reset_physics(env.context(target_id_last=1), np.random.default_rng(0))
    with pytest.raises(
        ValueError, match=r"action must be an integer in \[0, 4\) \(wobble_pairs=False\)"
    ):
        env.step_physics(4)
    with pytest.raises(ValueError, match=r"puts 'UG' there; placeable pairs are .*adds GU, UG"):
        env.actions_for("UAGGUGAAAAAGUCUG")
    wobble = RnaDesign(wobble_pairs=True)
    assert wobble.action_space.n == 6
    _, info = design(wobble, [4] * 5 + [5] * 6, mutation_threshold=0.0, **HAIRPIN_ONLY)
    assert info["sequence"] == "GGGGGUUUUUUUUUUU"


def test_options_are_checked_naming_the_value_and_the_choices():
    with pytest.raises(
        ValueError, match=r"improvement must be one of \['exhaustive', 'random'\], got 'greedy'"
    ):
        RnaDesign(improvement="greedy")
    with pytest.raises(ValueError, match=r"improvement='random' needs a fold budget"):
        RnaDesign(improvement="random")
    with pytest.raises(ValueError, match=r"improvement_folds must be None .* got -1"):
        RnaDesign(improvement_folds=-1)
    with pytest.raises(ValueError, match=r"wobble_pairs must be True or False, got 'yes'"):
        RnaDesign(wobble_pairs="yes")


def test_the_exhaustive_improvement_keeps_a_fold_budget_and_refuses_an_endless_threshold(env):
    """Without a budget a threshold above 9 could ask for 4^9 folds an episode: refused at reset,
    naming the value and the ways out; with ``improvement_folds`` the search stops at the budget."""
    with pytest.raises(
        ContextError, match=r"mutation_threshold=10 lets .* up to 4\^9 .* at most 9"
    ):
        env.reset_physics(env.context(mutation_threshold=10.0), np.random.default_rng(0))
    budget = RnaDesign(improvement_folds=20)
    actions = actions_writing(budget, PRION_DESIGNS[4], **PRION)
    _, info = design(budget, actions, mutation_threshold=10.0, **PRION)
    assert info["folds"] == 1 + 20 and info["hamming_distance"] > 0  # solved at fold 62 unbounded
    random_search = RnaDesign(improvement="random", improvement_folds=5)
    _, info = design(random_search, actions, mutation_threshold=10.0, **PRION)
    assert 1 < info["folds"] <= 1 + 5


def test_the_random_search_option_is_seeded_and_re_pairs_sites():
    env = RnaDesign(improvement="random", improvement_folds=32, wobble_pairs=True)
    near = (
        "CAGGUGAAAAAGUCUG"  # a wobble pair U-G at the stem's end: folds to ((((........)))), d = 2
    )
    assert fold(near) == "((((........))))"
    one = {"target_id_first": 1, "target_id_last": 1}
    actions = actions_writing(env, near, **one)
    reward, info = design(env, actions, mutation_threshold=2.0, **one)  # strict: d = 2 is not < 2
    assert info["folds"] == 1 and info["hamming_distance"] == 2 and info["sequence"] == near
    assert reward == pytest.approx(1 - 2 / 16)
    reward, info = design(env, actions, seed=3, mutation_threshold=2.5, **one)
    assert info["folds"] > 1 and info["sequence"] != near
    assert fold(info["sequence"]) == info["structure"]
    assert info["hamming_distance"] == sum(
        a != b for a, b in zip(info["structure"], HAIRPIN, strict=True)
    )
    assert info["hamming_distance"] < 2 and reward > 1 - 2 / 16
    pairs = {info["sequence"][i] + info["sequence"][15 - i] for i in range(5)}
    assert pairs <= {"AU", "CG", "GC", "UA", "GU", "UG"}  # a mismatched pair gets a new pair
    again = design(env, actions, seed=3, mutation_threshold=2.5, **one)[1]
    assert again == info  # the same seed, the same search


def test_local_improvement_never_exceeds_its_fold_budget(monkeypatch):
    env = RnaDesign(
        synthetic={"lengths": (16, 30), "min_multiloops": 0},
        improvement="random",
        improvement_folds=7,
        wobble_pairs=True,
    )
    calls = []

    def counting_fold(sequence: str) -> str:
        calls.append(sequence)
        return fold(sequence)

    monkeypatch.setattr(design_module, "fold", counting_fold)
    rng = np.random.default_rng(0)
    context = env.context(dataset="synthetic", target_id_last=20, mutation_threshold=1000.0)
    used = []
    for episode in range(30):
        calls.clear()
        env.reset_physics(context, np.random.default_rng(episode))
        terminated = False
        while not terminated:
            _, _, terminated = env.step_physics(int(rng.integers(6)))
        info = env.step_info()
        assert len(calls) == info["folds"] <= 1 + 7
        used.append(info["folds"])
    assert max(used) == 8  # the budget was reached, and respected


def test_state_radius_sets_how_many_sites_are_seen(env):
    for radius in (1, 5, 32):
        obs = env.reset_physics(
            env.context(state_radius=radius, target_id_first=7, target_id_last=7),
            np.random.default_rng(0),
        )
        assert obs.shape == env.base_observation_space.shape
        assert env.base_observation_space.contains(obs)
        rows = obs.reshape(-1, 4)
        seen = np.flatnonzero(rows.sum(axis=1))
        assert seen.tolist() == list(range(32 - radius, 33 + radius))  # each seen row is one-hot
        assert np.all(rows[seen].sum(axis=1) == 1)
    # the first site of target 1 opens a pair; the sites before the target are marked outside
    rows = env.reset_physics(
        env.context(state_radius=2, target_id_last=1), np.random.default_rng(0)
    ).reshape(-1, 4)
    assert rows[30:35].tolist() == [
        [0, 0, 0, 1],
        [0, 0, 0, 1],
        [0, 1, 0, 0],
        [0, 1, 0, 0],
        [0, 1, 0, 0],
    ]


def test_dataset_and_ids_choose_the_target(env):
    shipped = {}
    for dataset in ("eterna100_v1", "eterna100_v2", "rfam_taneda", "synthetic"):
        context = env.context(dataset=dataset, target_id_first=2, target_id_last=2)
        env.reset_physics(context, np.random.default_rng(0))
        assert env.step_info() == {"dataset": dataset, "target_id": 2}
        shipped[dataset] = env.target.structure
    assert len({shipped[name] for name in ("eterna100_v2", "rfam_taneda", "synthetic")}) == 3
    data = importlib.resources.files("contextrl.envs.rna") / "data"
    for dataset in ("eterna100_v1", "eterna100_v2", "rfam_taneda"):  # line 2 of the shipped file
        assert shipped[dataset] == (data / f"{dataset}.txt").read_text().splitlines()[1]
    v1, v2 = (  # puzzle 50 is one of the 19 that v2 changed
        env.targets.get(f"eterna100_v{version}", 50).structure for version in (1, 2)
    )
    assert v1 != v2
    drawn = set()
    context = env.context(dataset="rfam_taneda", target_id_first=3, target_id_last=5)
    for seed in range(40):
        env.reset_physics(context, np.random.default_rng(seed))
        drawn.add(env.target.id)
    assert drawn == {3, 4, 5}
    every = set()
    for seed in range(300):  # target_id_last = 0: up to the data set's last id
        env.reset_physics(env.context(dataset="rfam_taneda"), np.random.default_rng(seed))
        every.add(env.target.id)
    assert every == set(range(1, 30))


def test_ids_out_of_range_are_refused_naming_the_id(env):
    rng = np.random.default_rng(0)
    with pytest.raises(
        ContextError, match=r"target id 101 is out of range: .*eterna100_v2 .*1\.\.100"
    ):
        env.reset_physics(env.context(target_id_first=101), rng)
    with pytest.raises(
        ContextError, match=r"target_id_last: target id 30 .*rfam_taneda has ids 1\.\.29"
    ):
        env.reset_physics(env.context(dataset="rfam_taneda", target_id_last=30), rng)
    with pytest.raises(ContextError, match="target_id_first=9 comes after target_id_last=4"):
        env.reset_physics(env.context(target_id_first=9, target_id_last=4), rng)
    with pytest.raises(ContextError, match=r"target_id_first: value 0 is outside its bounds"):
        env.context(target_id_first=0)
    gym_env = gymnasium.make("contextrl/RnaDesign-v0", contexts={"target_id_first": 200})
    with pytest.raises(ContextError, match="target id 200 is out of range"):
        gym_env.reset(seed=0)


@pytest.mark.parametrize(
    "line, reason",
    [
        (
            "((...)",
            r"eterna100_v1 target 2: unbalanced brackets: '\(' at position 1 is never closed",
        ),
        (
            "(...))",
            r"eterna100_v1 target 2: unbalanced brackets: '\)' at position 6 closes nothing",
        ),
        ("((.x.))", r"eterna100_v1 target 2: bad character 'x' at position 4"),
        ("", "eterna100_v1 target 2: empty target"),
    ],
)
def test_malformed_targets_are_refused_naming_the_id_and_the_reason(tmp_path, line, reason):
    (tmp_path / "eterna100_v1.txt").write_text(f"((....))\n{line}\n(((...)))\n")
    with pytest.raises(TargetError, match=reason):
        RnaDesign(data_dir=tmp_path)


def test_data_dir_replaces_the_files_it_holds(tmp_path):
    (tmp_path / "rfam_taneda.txt").write_text("((....))\n.((....)).\n")
    env = RnaDesign(data_dir=tmp_path)
    assert env.targets.size("rfam_taneda") == 2 and env.targets.size("eterna100_v2") == 100
    env.reset_physics(
        env.context(dataset="rfam_taneda", target_id_first=2), np.random.default_rng(0)
    )
    assert env.target.structure == ".((....))."
    assert env.targets.get("rfam_taneda", 2).solution is None
    (tmp_path / "eterna100_v2.txt").write_text("((....))\n.((....)).\n")
    (tmp_path / "eterna100_v2_sample_solutions_vienna2.txt").write_text("GGAAAACC\n")
    with pytest.raises(TargetError, match="eterna100_v2: 1 solutions for 2 targets"):
        RnaDesign(data_dir=tmp_path)
    (tmp_path / "eterna100_v2_sample_solutions_vienna2.txt").write_text("GGAAAACC\nGGAAAACC\n")
    with pytest.raises(TargetError, match="eterna100_v2 target 2: a solution must be 10 bases"):
        RnaDesign(data_dir=tmp_path)
    (tmp_path / "eterna100_v2_sample_solutions_vienna2.txt").write_text("GGAAAACC\n(none)\n")
    targets = RnaDesign(data_dir=tmp_path).targets
    assert targets.get("eterna100_v2", 1).solution == "GGAAAACC"
    assert (
        targets.get("eterna100_v2", 2).solution is None
        and targets.get("eterna100_v2", 2).name == ""
    )
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(TargetError, match="holds none of the target files"):
        RnaDesign(data_dir=empty)


def test_synthetic_targets_are_seeded_rfam_like_and_come_with_a_solution():
    targets = TargetSets()
    first = targets.get("synthetic", 1)
    assert first == TargetSets().get("synthetic", 1)  # the same id is the same target anywhere
    assert first != targets.get("synthetic", 2)
    for target in (first, targets.get("synthetic", 2)):
        partners = pair_table(target.structure, "test")
        assert 50 <= len(target) <= 450 and np.mean(partners >= 0) >= 0.3
        assert count_multiloops(partners) >= 1
        assert fold(target.solution) == target.structure
    other_seed = TargetSets(synthetic=SyntheticTargets(seed=1)).get("synthetic", 1)
    assert other_seed.structure != first.structure
    with pytest.raises(ValueError, match=r"synthetic lengths: value 2 is outside its bounds"):
        SyntheticTargets(lengths=(2, 10))
    assert count_multiloops(pair_table("((..((...))..((...)).))", "x")) == 1
    assert count_multiloops(pair_table("((...))((...))", "x")) == 0  # the exterior loop is none


def test_render_shows_the_design():
    env = gymnasium.make(
        "contextrl/RnaDesign-v0",
        contexts={"target_id_first": 1, "target_id_last": 1},
        render_mode="rgb_array",
    )
    env.reset(seed=0)
    blank = env.render()
    for action in [2] * 5 + [0] * 6:
        env.step(action)
    frame = env.render()
    assert frame.shape == blank.shape and frame.dtype == np.uint8
    assert not np.array_equal(frame, blank)  # bases coloured in, the fold drawn below
    assert env.unwrapped.contextrl_env.render_text().splitlines()[1] == "GGGGGAAAAAACCCCC"
    env.close()


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_gymnasium_check_env_passes():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(
        "contextrl/RnaDesign-v0",
        contexts={"state_radius": contextrl.Categorical((3, 8)), "dataset": "rfam_taneda"},
        obs_context_features="all",
        render_mode="rgb_array",
    )
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


def test_gymnasium_episode_reports_the_design_in_info():
    env = gymnasium.make(
        "contextrl/CARLRnaDesignEnv-v0",
        contexts={"dataset": "eterna100_v2", "target_id_first": 1, "target_id_last": 1},
        wobble_pairs=True,  # the sample solution closes the stem with a GU pair
    )
    obs, info = env.reset(seed=0)
    assert info["target_id"] == 1 and env.observation_space.contains(obs)
    target = env.unwrapped.contextrl_env.targets.get("eterna100_v2", 1)
    for action in env.unwrapped.contextrl_env.actions_for(target.solution):
        obs, reward, terminated, truncated, info = env.step(action)
    assert terminated and not truncated and reward == 1.0
    assert info["solved"] and info["sequence"] == target.solution
    env.close()


def test_make_vec_gives_each_copy_its_context():
    envs = gymnasium.make_vec(
        "contextrl/RnaDesign-v0",
        num_envs=2,
        contexts=[
            {"dataset": "eterna100_v2", "target_id_first": 1, "target_id_last": 1},
            {"dataset": "rfam_taneda", "target_id_first": 4, "target_id_last": 4},
        ],
        obs_context_features=["dataset"],
    )
    obs, info = envs.reset(seed=0)
    assert list(info["dataset"]) == ["eterna100_v2", "rfam_taneda"]
    assert list(info["target_id"]) == [1, 4]
    np.testing.assert_array_equal(obs[:, -1], [1, 2])  # the dataset's index, shown to the agent
    finished = np.zeros(2, bool)
    for _ in range(500):
        obs, reward, terminated, truncated, info = envs.step(np.array([2, 2]))
        if terminated[0] and not finished[0]:  # the hairpin has 11 decisions (5 pairs + 6 loop)
            assert info["final_info"]["sequence"][0] == "GGGGGGGGGGGCCCCC"
        finished |= terminated
        if finished.all():
            break
    assert finished.all()
    envs.close()


def test_ppo_lowers_the_hamming_distance_on_short_synthetic_targets():
    """PPO on the host path, 8,192 steps, 50 short synthetic targets (12–20 nt), no local
    improvement, seed 0: the mean normalised Hamming distance of the last 100 episodes against the
    first 100.

    Measured (tests/helpers/margins.py) on LEARNA's task (4 actions, epoch-shuffled targets), the
    last 100 episodes' distance over the first 100's: default numerics, seeds 0–15: 0.12–0.70,
    median 0.36 (seed 0: 0.70; first 100 episodes 0.16–0.23, last 100 0.02–0.12); XLA's backend
    optimisation off, seeds 100–107: 0.23–0.72, median 0.43; as the suite compiles it (XLA's
    fusion emitters off and LLVM's level 0, conftest.py), seeds 0–7: 0.12–0.70, median 0.36 (the
    same with the emitters off alone). The bound of 0.85 (still
    15 % of the distance learned away) clears the worst seed by 0.13; the former 0.8 would clear it
    by 0.08.
    """
    statistics = learning.rna_short_targets([0])
    assert statistics["episodes"][0] > 400, statistics["episodes"]
    first, last = statistics["first_episodes"][0], statistics["last_episodes"][0]
    assert last < 0.85 * first, (first, last)


def test_the_train_test_example_spec_is_valid_for_rna_design():
    """The spec's fields belong to its protocol and its distributions fit RnaDesign's features.
    (The protocols train host environments once the shared host collector lands; until then
    ``parse_spec`` refuses host environments, so this checks the spec up to that point.)"""

    import yaml

    from contextrl.context.distributions import check_spec, sample
    from contextrl.experiments.spec import SPECS, parse_distribution

    path = ROOT / "examples" / "rna" / "visibility_rna_synthetic_to_eterna.yaml"
    data = yaml.safe_load(path.read_text())
    spec = SPECS[data["protocol"]](**data)  # every field known to the protocol
    assert spec.env == "RnaDesign" and contextrl.spec(spec.env).host
    space = RnaDesign.context_type.space
    env = RnaDesign()
    datasets = []
    for section in (spec.train, spec.test):
        resolved = check_spec(space, {k: parse_distribution(k, v) for k, v in section.items()})
        contexts = sample(space, resolved, 32, jax.random.key(0))
        for i in range(32):  # every drawn context names a valid target range
            env.target_range(env.context_values(contexts[i]))
        datasets.append(
            {space.features["dataset"].choices[d] for d in np.asarray(contexts.dataset)}
        )
    assert datasets == [{"synthetic"}, {"eterna100_v2", "rfam_taneda"}]


def test_targets_come_from_the_seed_given_to_reset():
    """Rfam-Taneda's 29 ids: the first 29 resets after ``reset(seed=...)`` are one epoch (each id
    once), in an order the seed fixes."""
    env = gymnasium.make("contextrl/RnaDesign-v0", contexts={"dataset": "rfam_taneda"})

    def drawn(seed: int) -> list[int]:
        ids = [env.reset(seed=seed)[1]["target_id"]]
        return ids + [env.reset()[1]["target_id"] for _ in range(28)]

    first = drawn(5)
    assert drawn(5) == first and drawn(6) != first and sorted(first) == list(range(1, 30))
    env.close()


def test_targets_are_shuffled_once_per_epoch_and_each_range_keeps_its_epoch(env):
    """As LEARNA, an epoch takes every id of the range once, in a shuffled order, and the next
    epoch reshuffles; a range's epoch goes on while other ranges' episodes come between."""
    rng = np.random.default_rng(7)
    everything = env.context(dataset="rfam_taneda")
    ids = []
    for _ in range(58):
        env.reset_physics(everything, rng)
        ids.append(env.target.id)
    assert sorted(ids[:29]) == sorted(ids[29:]) == list(range(1, 30)) and ids[:29] != ids[29:]
    ranges = {
        "first ten": env.context(dataset="rfam_taneda", target_id_last=10),
        "last ten": env.context(dataset="eterna100_v2", target_id_first=91),
    }
    seen = {name: [] for name in ranges}
    for _ in range(10):
        for name, context in ranges.items():
            env.reset_physics(context, rng)
            seen[name].append(env.target.id)
    assert sorted(seen["first ten"]) == list(range(1, 11))
    assert sorted(seen["last ten"]) == list(range(91, 101))
    for first in range(1, 71):  # 70 ranges: only the latest MAX_EPOCHS epochs are remembered
        env.reset_physics(env.context(target_id_first=first, target_id_last=first + 1), rng)
    assert len(env._epochs) == design_module.MAX_EPOCHS


def test_a_context_set_over_id_ranges_is_a_train_test_split():
    env = gymnasium.make(
        "contextrl/RnaDesign-v0",
        contexts={"train": {"target_id_last": 80}, "test": {"target_id_first": 81}},
    )
    seen = {"train": set(), "test": set()}
    env.reset(seed=0)
    for _ in range(60):  # round robin: train, test, train, ...
        _, info = env.reset()
        seen[info["context_id"]].add(info["target_id"])
    assert max(seen["train"]) <= 80 < min(seen["test"]) and len(seen["test"]) > 10
    env.close()
