"""`rrtq identify` on a real recording: the fitted model against the rover's true ZOH matrices.

The recording is made by `scripts/rrtq run` (composed, lock-step) of an open-loop probing
scenario; the truth is the zero-order hold (scipy's expm) of the scenario's continuous rover
model, as :mod:`rrtq_testing.controller_reference` writes it apart from the simulator.
"""

import json
import pathlib
import subprocess

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from rrtq_bringup import identify
from rrtq_controller.vf_lpc import KoopmanModel
from rrtq_testing import controller_reference as ref

ROOT = pathlib.Path(__file__).resolve().parents[4]
MASS, DAMPING = 40.0, 45.0


def probing_scenario(seed: int = 5) -> str:
    rng = np.random.default_rng(seed)
    forces = [[float(t), round(float(fx), 1), round(float(fy), 1)]
              for t, (fx, fy) in zip(np.arange(0.0, 12.0, 0.5),
                                     rng.uniform(-300.0, 300.0, (24, 2)))]
    return f"""
name: probe
seed: 1
bounds: {{x: [-100, 100], y: [-100, 100]}}
start: [0.0, 0.0]
goal: [90.0, 90.0]
duration: 12.0
perception_radius: 4.0
plant: {{model: rover, mass: {MASS}, stiffness: 0.0, damping: {DAMPING}, force_limit: 1000.0}}
controller:
  variant: open_loop
  forces: {forces}
obstacles: []
"""


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('identify')
    scenario = tmp / 'probe.yaml'
    scenario.write_text(probing_scenario())
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'run', str(scenario), '--out',
                           str(tmp / 'run'), '--mode', 'composed'],
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    return tmp / 'run' / 'run.mcap'


def cli(*argv):
    proc = subprocess.run([str(ROOT / 'scripts/rrtq'), 'identify', *map(str, argv)],
                          capture_output=True, text=True, timeout=120)
    return proc.returncode, proc.stdout, proc.stderr


def test_identified_model_is_the_true_zero_order_hold(recording, tmp_path):
    out = tmp_path / 'model.npz'
    code, stdout, stderr = cli(recording, '-o', out, '--holdout', '0.25')
    assert code == 0, stderr
    report = json.loads(stdout)
    phi, gamma = ref.zoh(*ref.rover(MASS, 0.0, DAMPING), 0.05)
    model = KoopmanModel.load(out)
    assert np.allclose(model.A, phi, atol=1e-6)
    assert np.allclose(model.B, gamma, atol=1e-8)
    assert report['held_out'] == report['samples'] - report['fitted_on'] > 0
    assert max(report['holdout_one_step_rmse']) < 1e-6
    assert report['open_loop_horizon_s'] == 2.0 and report['holdout_open_loop_windows'] > 0
    assert report['holdout_open_loop_position_rmse_m'] < 1e-4


def without_topic(src: pathlib.Path, dst: pathlib.Path, topic: str) -> None:
    """Copy a recording, leaving out one topic's messages."""
    with open(src, 'rb') as f, open(dst, 'wb') as g:
        writer = Writer(g)
        writer.start(profile='ros2')
        schemas, channels = {}, {}
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic == topic:
                continue
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id],
                    channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time)
        writer.finish()


def test_bad_inputs_exit_2_and_name_the_file(recording, tmp_path):
    missing = tmp_path / 'nope.mcap'
    code, _, err = cli(missing, '-o', tmp_path / 'm.npz')
    assert code == 2 and 'nope.mcap' in err
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'not an mcap file at all')
    code, _, err = cli(junk, '-o', tmp_path / 'm.npz')
    assert code == 2 and 'junk.mcap' in err
    stripped = tmp_path / 'no_cmd.mcap'
    without_topic(recording, stripped, '/cmd_force')
    code, _, err = cli(stripped, '-o', tmp_path / 'm.npz')
    assert code == 2 and 'no_cmd.mcap' in err and '/cmd_force' in err
    assert identify.main([str(recording), '-o', str(tmp_path / 'm.npz'),
                          '--holdout', '0.9']) == 2
    assert not (tmp_path / 'm.npz').exists()
