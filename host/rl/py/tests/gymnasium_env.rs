//! The Python package as Gymnasium users see it: `check_env` on every task, seeded episodes
//! that repeat, the expert and the reward of eq 4.29 seen through the binding, errors as
//! `ValueError`, and the vector environment against single environments. Needs the package in
//! the interpreter of `OCM_PYTHON` (scripts/setup.sh installs it into .venv).

use std::io::Write;
use std::process::{Command, Stdio};

// The chain of ocm-rl's own tests, so that both test suites drive the same robot. Helpers there
// that this file does not use are not dead code of theirs.
#[path = "../../tests/common/mod.rs"]
#[allow(dead_code)]
mod common;

const SCRIPT: &str = r#"
import json, sys, warnings
import numpy as np
import gymnasium
from gymnasium.utils.env_checker import check_env
import ocm_rl
from ocm_rl import OcmEnv, OcmVectorEnv, env_id

chain = json.loads(sys.stdin.read())
out = {}

# 1. Gymnasium's checker on every task, through gymnasium.make (so the spec is checked too).
# The only warnings allowed are the unbounded observation space's (velocities and forces
# have no finite bound).
allowed = ("A Box observation space minimum value is -infinity",
           "A Box observation space maximum value is infinity")
assert set(ocm_rl.TASKS) == {"circle", "star", "weight", "force", "ellipse"}, ocm_rl.TASKS
for task in ocm_rl.TASKS:
    env = gymnasium.make(env_id(task), chain=chain).unwrapped
    assert isinstance(env, OcmEnv) and env.task == task
    assert env.observation_space.shape == (40,) and env.observation_space.dtype == np.float32
    assert env.action_space.shape == (3,) and env.action_space.dtype == np.float32
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    unexpected = [str(w.message) for w in caught
                  if not any(a in str(w.message) for a in allowed)]
    assert not unexpected, (task, unexpected)

# 2. A seeded episode played twice gives the same observations and rewards; another seed differs.
def play(task, seed, actions):
    env = OcmEnv(task, chain=chain)
    obs, info = env.reset(seed=seed)
    assert info["episode_seed"] == seed
    trace, rewards, ends = [obs], [], None
    for k, a in enumerate(actions):
        obs, r, term, trunc, info = env.step(a)
        trace.append(obs)
        rewards.append(r)
        if term or trunc:
            ends = (k + 1, term, trunc)
            break
    return np.array(trace), np.array(rewards), ends

actions = np.random.default_rng(3).uniform(-0.2, 0.2, size=(100, 3)).astype(np.float32)
for task in ocm_rl.TASKS:
    a, ra, ea = play(task, 11, actions)
    b, rb, eb = play(task, 11, actions)
    c, _, _ = play(task, 12, actions)
    assert a.shape == b.shape and np.array_equal(a, b) and np.array_equal(ra, rb), task
    assert ea == eb and ea is not None, (task, ea)
    assert not np.array_equal(a[0], c[0]), task
    assert np.all(np.isfinite(a)), task

# 3. The inverse-model expert through the binding tracks the circle to well under a millimetre,
# the episode is truncated after its 100 points, and the reward is eq 4.29 with alpha = 1:
# 1 / (1 + 100 delta_q), delta_q the TCP distance to the target in metres.
env = OcmEnv("circle", chain=chain)
env.reset(seed=5)
errors, steps = [], 0
while True:
    obs, r, term, trunc, info = env.step(env.expert_action())
    steps += 1
    d = float(np.linalg.norm(info["tcp_m"] - info["target_m"]))
    assert abs(d - info["position_error_m"]) < 1e-12
    assert abs(r - 1.0 / (1.0 + 100.0 * info["position_error_m"])) < 1e-12, (r, info)
    errors.append(info["position_error_m"])
    if term or trunc:
        break
assert (steps, term, trunc) == (100, False, True), (steps, term, trunc)
out["expert_mean_error_m"] = float(np.mean(errors))
assert out["expert_mean_error_m"] < 5e-4, out

# 4. Bad input is a ValueError with the Rust message, and leaves the episode untouched.
env = OcmEnv("star", chain=chain)
twin = OcmEnv("star", chain=chain)
env.reset(seed=2); twin.reset(seed=2)
for bad, words in (([np.nan, 0, 0], "finite"), ([0, np.inf, 0], "finite"),
                   ([0.1, 0.2], "expected 3")):
    try:
        env.step(np.array(bad, dtype=np.float32))
    except ValueError as e:
        assert words in str(e), (bad, str(e))
    else:
        raise AssertionError(f"{bad} was accepted")
good = np.array([0.1, -0.1, 0.3], dtype=np.float32)
assert np.array_equal(env.step(good)[0], twin.step(good)[0])
_, _, _, _, info = env.step(np.array([3.0, 0, 0], dtype=np.float32))
assert info["clipped"] is True
for make, words in ((lambda: OcmEnv("square", chain=chain), "unknown task"),
                    (lambda: OcmEnv("circle"), "exactly one of"),
                    (lambda: OcmEnv("circle", chain=dict(chain, link_mass_kg=-1.0)), "link_mass_kg"),
                    (lambda: OcmEnv("circle", chain=chain, substeps=0), "substeps"),
                    (lambda: OcmEnv("circle", chain=chain).step([0, 0, 0]), "reset")):
    try:
        make()
    except ValueError as e:
        assert words in str(e), (words, str(e))
    else:
        raise AssertionError(f"no ValueError ({words})")

try:
    OcmEnv("circle", model="/nonexistent/surrogate.json")
except FileNotFoundError as e:
    assert "/nonexistent/surrogate.json" in str(e), str(e)
else:
    raise AssertionError("a missing model file was accepted")

# 5. The vector environment equals single environments with the documented seeds (environment
# i plays seed + i, its k-th restart seed + i + k n), with same-step autoreset.
n, seed = 3, 40
venv = gymnasium.make_vec(env_id("weight"), num_envs=n, vectorization_mode="vector_entry_point",
                          chain=chain)
assert isinstance(venv, OcmVectorEnv) and venv.num_envs == n
assert venv.observation_space.shape == (n, 40) and venv.single_action_space.shape == (3,)
singles = [OcmEnv("weight", chain=chain) for _ in range(n)]
restarts = [0] * n
vobs, vinfo = venv.reset(seed=seed)
assert list(vinfo["episode_seed"]) == [seed + i for i in range(n)]
for i, e in enumerate(singles):
    assert np.array_equal(vobs[i], e.reset(seed=seed + i)[0]), i
rng = np.random.default_rng(9)
ends = {"terminated": 0, "truncated": 0}
for step in range(130):
    # Environments 0 and 1 follow the expert with a little noise and run to their time limit;
    # environment 2 acts at random and loses the TCP within a few steps.
    expert = np.stack([e.expert_action() for e in singles])
    assert np.array_equal(expert, venv.expert_actions())
    acts = (expert + rng.normal(0.0, 0.02, size=(n, 3))).astype(np.float32)
    acts[2] = rng.uniform(-0.6, 0.6, size=3)
    vobs, vrew, vterm, vtrunc, vinfo = venv.step(acts)
    assert vobs.dtype == np.float32 and vrew.dtype == np.float64
    for i, e in enumerate(singles):
        obs, r, term, trunc, info = e.step(acts[i])
        assert r == vrew[i] and term == vterm[i] and trunc == vtrunc[i], (step, i)
        if term or trunc:
            ends["terminated" if term else "truncated"] += 1
            assert vinfo["_final_obs"][i]
            assert np.array_equal(vinfo["final_obs"][i], obs), (step, i)
            assert vinfo["final_info"]["position_error_m"][i] == info["position_error_m"]
            restarts[i] += 1
            obs, _ = e.reset(seed=seed + i + restarts[i] * n)
        else:
            assert "_final_obs" not in vinfo or not vinfo["_final_obs"][i]
            assert vinfo["position_error_m"][i] == info["position_error_m"]
        assert np.array_equal(vobs[i], obs), (step, i)
assert ends["truncated"] == 2 and ends["terminated"] >= 3, ends
out["vector_episode_ends"] = ends
print(json.dumps(out))
"#;

#[test]
fn gymnasium_checks_determinism_errors_and_the_vector_env() {
    let Some(python) = ocm_datadir::require_python(&["gymnasium", "ocm_rl"]) else {
        return;
    };
    let chain = serde_json::to_string(common::robot().chain()).unwrap();
    let mut child = Command::new(python)
        .args(["-c", SCRIPT])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(chain.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the Python checks failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let err = v["expert_mean_error_m"].as_f64().unwrap();
    assert!(err < 5e-4, "expert mean error {err} m");
    assert_eq!(v["vector_episode_ends"]["truncated"].as_u64(), Some(2));
    assert!(v["vector_episode_ends"]["terminated"].as_u64().unwrap() >= 3);
}
