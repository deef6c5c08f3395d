# ruff: noqa: E501 - the table keeps one case per line
"""Bad input never becomes a traceback or a silent result: exit code 2, the field or file named.

One table over command-line options, scenario TOML, planner TOML (with the delta-v model),
refit CSV and run-index rows. Every case runs ``etp`` in this process with the
simulation replaced by a function that fails the test: bad input must be refused
before anything is simulated.
"""

import json

import pytest

from harm_calibration.cli import main
from tests.harm_calibration.cli.conftest import HEAD_ON

SCENARIO = HEAD_ON.format(name="short", duration=2.0)
GOOD_CSV = (
    "dv,mais3,area\n5,0,front\n12,1,side\n20,0,rear\n25,1,front\n8,1,front\n15,0,side\n30,1,rear\n3,0,rear\n"
)


def _scenario(old: str = "", new: str = "", *, extra: str = "") -> str:
    """The short scenario with ``old`` replaced by ``new`` (which must occur) and ``extra`` appended."""
    if old:
        assert old in SCENARIO, old
    return (SCENARIO.replace(old, new, 1) if old else SCENARIO) + extra


def _user(**fields: str) -> str:
    """A third road user whose fields (TOML values) override a scripted car's."""
    values = {"name": '"third"', "type": '"car"', "s0": "50.0"} | fields
    return "\n[[road_users]]\n" + "".join(f"{k} = {v}\n" for k, v in values.items())


def _csv(*rows: str, header: str = "dv,mais3,area") -> str:
    return "\n".join([header, *rows]) + "\n"


def _index(*rows) -> str:
    good = {
        "run_id": "a__ethical__s0", "scenario": "a", "planner": "ethical", "seed": 0, "outcome": "goal",
        "collisions": 0, "max_harm_measured": 0.0, "max_harm_predicted": 0.0, "min_distance": 5.0,
        "min_ttc": "inf", "max_collision_probability": 0.0,
    }  # fmt: skip
    return "".join((json.dumps(good | row) if isinstance(row, dict) else row) + "\n" for row in rows)


# (id, argv, files {name: text or bytes}, what the message must contain). "{d}" is the
# test's folder (in argv and message); files are written there.
CASES = [
    # --------------------------------------------------------------- command-line options
    ("seed-negative", ["run", "{d}/s.toml", "--seed", "-1"], {"s.toml": SCENARIO}, "--seed must be an integer >= 0"),
    ("seeds-negative", ["demo", "--scenarios", "{d}/s.toml", "--seeds", "-1"], {"s.toml": SCENARIO}, "--seeds must"),
    ("seeds-text", ["demo", "--seeds", "a,b"], {}, "--seeds must be comma-separated integers"),
    ("seeds-twice", ["demo", "--seeds", "1,1"], {}, "--seeds lists 1 more than once"),
    ("random-negative", ["demo", "--random", "-3"], {}, "--random must be an integer >= 0"),
    ("random-huge", ["demo", "--random", "100000000"], {}, "one batch takes at most 100000"),
    ("random-float", ["demo", "--random", "1e8"], {}, "argument --random: invalid int value"),
    ("workers-zero", ["demo", "--workers", "0"], {}, "--workers must be >= 1"),
    ("planner-unknown", ["demo", "--planners", "reckless"], {}, "unknown planner 'reckless'; allowed: ethical"),
    ("planners-twice", ["demo", "--planners", "ethical,ethical"], {}, "--planners lists ethical more than once"),
    ("planners-empty", ["demo", "--planners", ","], {}, "--planners must name at least one item"),
    ("scenario-unknown", ["demo", "--scenarios", "nope"], {}, "nope"),
    ("scenario-twice", ["demo", "--scenarios", "{d}/s.toml,{d}/s.toml"], {"s.toml": SCENARIO}, "more than once"),
    ("scenario-alias", ["demo", "--scenarios", "{d}/s.toml,{d}/x/../s.toml"], {"s.toml": SCENARIO, "x/.keep": ""}, "are one run"),
    ("run-unknown", ["run", "no_such_scenario"], {}, "no_such_scenario"),
    ("noise-negative", ["run", "{d}/s.toml", "--noise", "-1"], {"s.toml": SCENARIO}, "--noise must lie in [0, 10] m"),
    ("replan-zero", ["run", "{d}/s.toml", "--replan-rate", "0"], {"s.toml": SCENARIO}, "--replan-rate must lie in"),
    ("replan-huge", ["run", "{d}/s.toml", "--replan-rate", "1e9"], {"s.toml": SCENARIO}, "--replan-rate must lie in"),
    ("keep-unknown", ["run", "{d}/s.toml", "--keep-recordings", "some"], {"s.toml": SCENARIO}, "invalid choice"),
    ("out-is-file", ["run", "{d}/s.toml", "--out", "{d}/s.toml"], {"s.toml": SCENARIO}, "is a file, not a folder"),
    ("harm-dv-negative", ["harm", "--dv", "-5", "--area", "front"], {}, "--dv must lie in [0, 100] m/s"),
    ("harm-dv-nan", ["harm", "--dv", "nan", "--area", "front"], {}, "--dv must lie in [0, 100] m/s"),
    ("harm-dv-huge", ["harm", "--dv", "1e308", "--area", "front"], {}, "--dv must lie in [0, 100] m/s"),
    ("harm-area", ["harm", "--dv", "5", "--area", "roof"], {}, "unknown area 'roof'"),
    ("harm-partner", ["harm", "--dv", "5", "--partner", "spaceship"], {}, "spaceship"),
    ("harm-model", ["harm", "--dv", "5", "--area", "front", "--model", "bogus"], {}, "unknown harm model 'bogus'"),
    ("harm-ego-mass", ["harm", "--dv", "5", "--area", "front", "--ego-mass", "0"], {}, "--ego-mass must lie in"),
    ("plan-cycles", ["plan", "--cycles", "0"], {}, "--cycles must be >= 1"),
    ("bench-repetitions", ["bench", "--repetitions", "0"], {}, "--repetitions must be >= 1"),
    ("near-crash-top", ["near-crash", "{d}", "--top", "0"], {}, "--top must be >= 1"),
    ("impacts-workers", ["impacts", "--out", "{d}/o", "--workers", "0"], {}, "--workers must be >= 1"),
    ("unknown-command", ["teleport"], {}, "invalid choice: 'teleport'"),
    # -------------------------------------------------------------------- scenario TOML
    ("user-speed-1e6", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(behaviour='{ kind = "scripted", speed = 1e6 }'))}, "{d}/s.toml: road_users[2].behaviour.speed must lie in [0, 70] m/s"),
    ("road-length-tiny", ["run", "{d}/s.toml"], {"s.toml": _scenario("length = 300.0", "length = 0.001")}, "{d}/s.toml: road.length must lie in [10, 20000] m"),
    ("ego-mass-1e30", ["run", "{d}/s.toml"], {"s.toml": _scenario("[ego]\n", "[ego]\nmass = 1e30\n")}, "{d}/s.toml: ego.mass must lie in"),
    ("ego-s0-negative", ["run", "{d}/s.toml"], {"s.toml": _scenario("s0 = 10.0\nspeed = 10.0", "s0 = -50.0\nspeed = 10.0")}, "{d}/s.toml: ego.s0 must lie in"),
    ("goal-beyond-road", ["run", "{d}/s.toml"], {"s.toml": _scenario("[ego]\n", "[ego]\ngoal_s = 5000.0\n")}, "{d}/s.toml: ego.goal_s must lie between"),
    ("lane-width-huge", ["run", "{d}/s.toml"], {"s.toml": _scenario("length = 300.0", "length = 300.0\nlane_width = 1e6")}, "{d}/s.toml: road.lane_width must lie in"),
    ("user-width-tiny", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(width="1e-9"))}, "{d}/s.toml: road_users[2].width must lie in"),
    ("speed-limit-tiny", ["run", "{d}/s.toml"], {"s.toml": _scenario("length = 300.0", "length = 300.0\nspeed_limit = 1e-9")}, "{d}/s.toml: road.speed_limit must lie in"),
    ("lanes-bool", ["run", "{d}/s.toml"], {"s.toml": _scenario("length = 300.0", "length = 300.0\nlanes = true")}, "{d}/s.toml: road.lanes must be an integer"),
    ("duration-huge", ["run", "{d}/s.toml"], {"s.toml": _scenario("duration = 2.0", "duration = 1e9")}, "{d}/s.toml: scenario.duration must lie in"),
    ("duration-text", ["run", "{d}/s.toml"], {"s.toml": _scenario("duration = 2.0", 'duration = "long"')}, "{d}/s.toml: duration must be a finite number"),
    ("unknown-key", ["run", "{d}/s.toml"], {"s.toml": _scenario("[ego]\n", "[ego]\nsped = 3.0\n")}, "{d}/s.toml: unknown key 'ego.sped'"),
    ("not-utf8", ["run", "{d}/s.toml"], {"s.toml": SCENARIO.encode() + b"# \xff\xfe\n"}, "{d}/s.toml: not UTF-8 text"),
    ("not-toml", ["run", "{d}/s.toml"], {"s.toml": "name = [\n"}, "{d}/s.toml: not valid TOML"),
    ("user-type", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(type='"spaceship"'))}, "{d}/s.toml: road_users[2]: type: unknown road-user type 'spaceship'"),
    ("user-name", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(name='"two words"'))}, "{d}/s.toml: road_users[2]: road user name must be an identifier"),
    ("user-twice", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(name='"east"'))}, "{d}/s.toml: road_users: duplicate names ['east']"),
    ("user-no-name", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[[road_users]]\ntype = "car"\n')}, "{d}/s.toml: missing key 'road_users[2].name'"),
    ("user-beyond-road", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(s0="900.0"))}, "{d}/s.toml: road_users[2] (third).s0 must lie on its road"),
    ("user-mass", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(mass="1e9"))}, "{d}/s.toml: road_users[2].mass must lie in"),
    ("user-lane", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(route="{ lane = 5 }"))}, "{d}/s.toml: road_users[2] (third).route.lane must be < road.lanes (2), got 5"),
    ("behaviour-kind", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(behaviour='{ kind = "teleport" }'))}, "{d}/s.toml: road_users[2].behaviour.kind: unknown behaviour kind 'teleport'"),
    ("profile-times", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(behaviour='{ speed_profile = [[2.0, 5.0], [1.0, 3.0]] }'))}, "{d}/s.toml: road_users[2].behaviour.speed_profile times must be >= 0 and strictly increasing"),
    ("lateral-huge", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(behaviour='{ lateral = [[1.0, 500.0]] }'))}, "{d}/s.toml: road_users[2].behaviour.lateral must lie in [-20, 20] m"),
    ("friction", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra="\n[contact]\nfriction = 5.0\n")}, "{d}/s.toml: contact.friction must lie in"),
    ("restitution", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[contact]\nrestitution = [{ a = "car", b = "car", e = 2.0 }]\n')}, "{d}/s.toml: contact.restitution[0].e must lie in"),
    ("contact-mode", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[contact]\nmode = "jelly"\n')}, "{d}/s.toml: contact.mode: unknown contact mode 'jelly'"),
    ("restitution-law", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra="\n[contact.restitution_law]\ne_low = 1.5\n")}, "{d}/s.toml: contact.restitution_law.e_low must lie in [0, 1]"),
    ("restitution-scale-pair", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[contact]\nrestitution = [{ a = "car", b = "truck", speed_scale = 1e6 }]\n')}, "{d}/s.toml: contact.restitution[0].speed_scale must lie in [0.1, 100] m/s"),
    ("restitution-both", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[contact]\nrestitution = [{ a = "car", b = "truck", e = 0.1, e_low = 0.3 }]\n')}, "give either e (a constant) or some of e_high, e_low, speed_scale"),
    ("sensor-range", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra="\n[sensor]\nrange = -5.0\n")}, "{d}/s.toml: sensor.range"),
    ("scenario-folder", ["run", "{d}/folder.toml"], {"folder.toml/x": ""}, "cannot read scenario file {d}/folder.toml"),
    ("debris-under-ego", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra='\n[[debris]]\nname = "rock"\ns = 11.0\noffset = -1.75\nlength = 1.0\nwidth = 1.0\n')}, "debris[0] (rock) lies under the ego at the start"),
    ("lane-change-off-road", ["run", "{d}/s.toml"], {"s.toml": _scenario(extra=_user(behaviour='{ kind = "scripted", speed = 5.0, events = [{ when = { time = 1.0 }, do = { change_lane = -1 } }] }'))}, "road_users[2] (third).behaviour.events[0].do.change_lane = -1 takes it to lane -1, off the road"),
    # ------------------------------------------------------------------- planner TOML
    ("n-speeds-float", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[sampling]\nn_speeds = 2.5\n"}, "{d}/p.toml: sampling.n_speeds must be an integer"),
    ("n-speeds-huge", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[sampling]\nn_speeds = 100000\n"}, "{d}/p.toml: sampling.n_speeds must be an integer in 1..200"),
    ("dt-tiny", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[sampling]\ndt = 1e-7\n"}, "{d}/p.toml: sampling.dt must lie in [0.001, 1.0] s"),
    ("horizon-long", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[sampling]\nhorizons = [100.0]\n"}, "{d}/p.toml: sampling.horizons must lie in"),
    ("grid-points", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[sampling]\nn_speeds = 200\nn_offsets = 200\nhorizons = [10.0]\ndt = 0.05\n"}, "{d}/p.toml: sampling.n_speeds x n_offsets x steps = 40000 x 201 = 8040000 points per cycle; at most 2000000"),
    ("weight-negative", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[weights]\nbayes = -1.0\n"}, "{d}/p.toml: weights.bayes must be >= 0"),
    ("weight-text", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": '[weights]\nbayes = "high"\n'}, "{d}/p.toml: weights.bayes must be a finite number"),
    ("harm-model-file", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": '[risk]\nharm_model = "bogus"\n'}, "{d}/p.toml: risk.harm_model: unknown harm model 'bogus'"),
    ("r-max", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[risk]\nmax_acceptable_risk = 2.0\n"}, "{d}/p.toml: risk.max_acceptable_risk must lie in [0, 1]"),
    ("a-max", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[vehicle]\na_max = -1.0\n"}, "{d}/p.toml: vehicle.a_max"),
    ("boolean-text", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": '[risk]\nboundary_harm = "yes"\n'}, "{d}/p.toml: risk.boundary_harm must be true or false"),
    ("config-unknown-key", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[weights]\nbogus = 1.0\n"}, "{d}/p.toml: unknown key 'weights.bogus'"),
    ("config-preset", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": 'preset = "nope"\n'}, "{d}/p.toml: unknown planner preset 'nope'"),
    ("config-not-toml", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[weights\n"}, "{d}/p.toml: not valid TOML"),
    ("config-not-utf8", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": b"[weights]\n# \xff\n"}, "{d}/p.toml: not UTF-8 text"),
    ("config-missing", ["run", "{d}/s.toml", "--config", "{d}/nope.toml"], {"s.toml": SCENARIO}, "cannot read planner configuration file {d}/nope.toml"),
    ("desired-speed", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "desired_speed = -3.0\n"}, "{d}/p.toml: desired_speed"),
    # ------------------------------------------------- delta-v model (planner TOML)
    ("dv-model", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": '[risk]\ndelta_v_model = "bogus"\n'}, "{d}/p.toml: risk.delta_v_model: unknown delta-v model 'bogus'"),
    ("dv-correction-retired", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": '[risk]\ndelta_v_correction = "c.json"\n'}, "{d}/p.toml: unknown key 'risk.delta_v_correction'"),
    ("impulse-ratio", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[risk]\nimpulse_ratio = -0.3\n"}, "{d}/p.toml: risk.impulse_ratio must be >= 0"),
    ("restitution-high", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[risk.restitution_law]\ne_high = 1.5\n"}, "restitution_law.e_high must lie in [0, 1]"),
    ("restitution-scale", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[risk.restitution_law]\nspeed_scale = 0.0\n"}, "restitution_law.speed_scale must be > 0"),
    ("restitution-key", ["run", "{d}/s.toml", "--config", "{d}/p.toml"], {"s.toml": SCENARIO, "p.toml": "[risk.restitution_law]\ne_mid = 0.2\n"}, "{d}/p.toml: unknown key 'risk.restitution_law.e_mid'"),
    # ------------------------------------------------------------------------ refit CSV
    ("csv-missing-column", ["refit-harm", "{d}/r.csv"], {"r.csv": _csv("5,front", header="dv,area")}, "{d}/r.csv: neither crash records"),
    ("csv-dv-negative", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "-1,0,front\n"}, "{d}/r.csv row 9: dv must be finite and >= 0"),
    ("csv-dv-text", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "fast,0,front\n"}, "{d}/r.csv row 9: dv must be a number"),
    ("csv-label", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "5,2,front\n"}, "{d}/r.csv row 9: mais3 must be 0 or 1"),
    ("csv-area", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "5,1,roof\n"}, "{d}/r.csv row 9: area 'roof'"),
    ("csv-weight", ["refit-harm", "{d}/r.csv"], {"r.csv": _csv("5,1,front,-2", header="dv,mais3,area,weight")}, "{d}/r.csv row 1: weight must be finite and >= 0"),
    ("csv-ragged", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "5,1,front,extra\n"}, "{d}/r.csv row 9: has more fields than the header"),
    ("csv-short", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV + "5\n"}, "{d}/r.csv row 9: has fewer fields than the header"),
    ("csv-not-utf8", ["refit-harm", "{d}/r.csv"], {"r.csv": GOOD_CSV.encode() + b"5,1,\xff\n"}, "{d}/r.csv: not UTF-8 text"),
    ("csv-empty", ["refit-harm", "{d}/r.csv"], {"r.csv": ""}, "{d}/r.csv: empty file"),
    ("csv-header-only", ["refit-harm", "{d}/r.csv"], {"r.csv": "dv,mais3,area\n"}, "{d}/r.csv: no records"),
    ("csv-separable", ["refit-harm", "{d}/r.csv", "--model", "ignore_angle"], {"r.csv": _csv("1,0", "2,0", "8,1", "9,1", header="dv,mais3")}, "{d}/r.csv: the outcomes are separable"),
    ("csv-constant-dv", ["refit-harm", "{d}/r.csv", "--model", "ignore_angle"], {"r.csv": _csv("5,0", "5,1", "5,1", header="dv,mais3")}, "{d}/r.csv: the records cannot tell parameters ['c0', 'c1'] apart (rank-deficient design)"),
    ("csv-all-zero", ["refit-harm", "{d}/r.csv", "--model", "ignore_angle"], {"r.csv": _csv("1,0", "5,0", "9,0", header="dv,mais3")}, "{d}/r.csv: every record has mais3 = 0"),
    ("csv-model", ["refit-harm", "{d}/r.csv", "--model", "ref_speed_ignore_angle"], {"r.csv": GOOD_CSV}, "not logistic"),
    ("csv-impacts-model", ["refit-harm", "{d}/r.csv", "--model", "gidas"], {"r.csv": "status,model_a,harm_measured_a,dv_predicted_a,area_predicted_a,model_b,harm_measured_b,dv_predicted_b,area_predicted_b\nok,reduced_sym,0.1,5,front,reduced_sym,0.1,5,front\n"}, "{d}/r.csv: no measured body was assessed with model 'gidas'"),
    # ----------------------------------------------------------------------- index rows
    ("index-seed", ["near-crash", "{d}"], {"index.jsonl": _index({"seed": "x"})}, "index.jsonl line 1: seed must be an integer"),
    ("index-run-id", ["near-crash", "{d}"], {"index.jsonl": _index({}, {"run_id": None})}, "index.jsonl line 2: run_id must be a string"),
    ("index-list", ["near-crash", "{d}"], {"index.jsonl": _index({}, "[1, 2, 3]")}, "index.jsonl line 2: not a JSON object"),
    ("index-severity", ["near-crash", "{d}"], {"index.jsonl": _index({"severity": "high"})}, "index.jsonl line 1: severity must be a number"),
    ("index-missing-key", ["near-crash", "{d}"], {"index.jsonl": '{"run_id": "a"}\n'}, "index.jsonl line 1: missing"),
    ("index-folder", ["near-crash", "{d}"], {"index.jsonl/x": ""}, "index.jsonl"),
]  # fmt: skip


def _never(*args, **kwargs):
    raise AssertionError("bad input reached the simulation")


@pytest.mark.parametrize(("argv", "files", "message"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_exit_2_naming_the_field_or_file(tmp_path, capsys, monkeypatch, argv, files, message):
    import mujoco_world.experiments.batch as batch
    import mujoco_world.loop.runner as runner

    monkeypatch.setattr(runner, "run_scenario", _never)
    monkeypatch.setattr(batch, "run_scenario", _never)
    monkeypatch.setattr(batch, "run_batch", _never)
    monkeypatch.chdir(tmp_path)
    for name, content in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
    code = main([a.format(d=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert code == 2, err
    assert message.format(d=tmp_path) in err, err
    assert "Traceback" not in err


def test_the_table_is_large_enough():
    assert len(CASES) >= 60
    assert len({c[0] for c in CASES}) == len(CASES)
