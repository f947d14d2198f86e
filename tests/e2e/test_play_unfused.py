"""`fusiond play` exits non-zero when the daemon did not fuse everything it was sent, naming the sensor,
how many and why (from the daemon's health); through the real `fusiond run` and `fusiond play` on loopback.

The daemon here expects its IMU as JSON while play sends the bag's CDR (a mismatched `encoding`): every
IMU sample is dropped undecoded. A daemon that fuses everything makes play exit 0 (tests/e2e/test_daemon.py's
play test)."""

from __future__ import annotations

import re
import subprocess

import pytest

from tests.support.daemon import (
    ROOT, client_session, daemon_process, free_port, fusiond_cmd, health, wait_daemon_ready, wait_until, write_config,
)

pytestmark = pytest.mark.e2e


def test_play_exits_1_naming_what_the_daemon_did_not_fuse(jackal_bag, tmp_path):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    daemon_config = tmp_path / "imu_json.toml"
    daemon_config.write_text(config.read_text().replace('key = "imu/data"', 'key = "imu/data"\nencoding = "json"'))
    log = tmp_path / "daemon.log"
    with daemon_process(daemon_config, log) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log)
        play = subprocess.run(fusiond_cmd("play", str(jackal_bag), "--config", str(config), "--rate", "0",
                                          "--duration", "5", "--connect", f"tcp/127.0.0.1:{port}"),
                              capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert play.returncode == 1, (play.stdout, play.stderr)
    m = re.search(r"sensor 'imu': (\d+) of (\d+) samples sent were not fused \((\d+) ", play.stderr)
    assert m, play.stderr
    assert 0 < int(m.group(1)) == int(m.group(2)) == int(m.group(3))
    assert "sensor 'wheel'" not in play.stderr.split("play_finished")[-1]  # the odometry was all fused
    assert re.search(r"played \d+ messages", play.stdout)  # the summary still on stdout


def test_play_exits_1_when_no_daemon_answers_and_0_when_told_not_to_ask(jackal_bag, tmp_path):
    """No daemon on the config's endpoint: nothing sent can be known fused, so play says so and exits 1 after
    playing (it may feed a daemon it cannot reach for health); `--wait 0` asks nothing and exits 0."""
    config = write_config(tmp_path / "jackal.toml", free_port())
    common = ("play", str(jackal_bag), "--config", str(config), "--rate", "0", "--duration", "1", "--no-multicast")
    play = subprocess.run(fusiond_cmd(*common, "--wait", "0.5"), capture_output=True, text=True, timeout=120,
                          cwd=ROOT)
    assert play.returncode == 1 and re.search(r"played \d+ messages", play.stdout), (play.stdout, play.stderr)
    assert "no daemon answered on 'fusiond/health'" in play.stderr and "within --wait 0.5 s" in play.stderr
    unasked = subprocess.run(fusiond_cmd(*common, "--wait", "0"), capture_output=True, text=True, timeout=120,
                             cwd=ROOT)
    assert unasked.returncode == 0 and "no daemon answered" not in unasked.stderr, unasked.stderr


def test_play_refuses_a_configured_topic_the_bag_lacks_unless_allowed(jackal_bag, tmp_path):
    """A misspelt key would play a bag the daemon never hears part of: exit 2 naming the sensor and the bag topic
    it may have meant, before any session is opened; `--allow-missing` plays without it."""
    config = write_config(tmp_path / "jackal.toml", free_port())
    config.write_text(config.read_text().replace('key = "imu/data"', 'key = "imu/dat"'))
    common = ("play", str(jackal_bag), "--config", str(config), "--rate", "0", "--duration", "1", "--no-multicast",
              "--wait", "0")
    refused = subprocess.run(fusiond_cmd(*common), capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert refused.returncode == 2 and "sensor 'imu': topic /imu/dat is not in the bag" in refused.stderr, refused
    assert "/imu/data" in refused.stderr and "--allow-missing" in refused.stderr and not refused.stdout
    allowed = subprocess.run(fusiond_cmd(*common, "--allow-missing"), capture_output=True, text=True, timeout=120,
                             cwd=ROOT)
    assert allowed.returncode == 0 and re.search(r"played \d+ messages \(wheel=\d+ imu=0\)", allowed.stdout), allowed


def test_play_says_when_the_daemon_restarted_while_it_played(jackal_bag, tmp_path):
    """The daemon stopped and started again 2 s into a 6 s play at the recorded pace: the health answering after
    the play is another Zenoh session, whose counts started over. play says the daemon restarted (its ids), exit
    1, rather than calling the first daemon's fused samples "unaccounted"."""
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    log1, log2 = tmp_path / "first.log", tmp_path / "second.log"
    with daemon_process(config, log1) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log1)
        play = subprocess.Popen(fusiond_cmd("play", str(jackal_bag), "--config", str(config), "--rate", "1",
                                            "--duration", "6", "--connect", f"tcp/127.0.0.1:{port}"),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        wait_until(lambda: health(session, 0.5) and health(session, 0.5)["sensors"]["wheel"]["applied"] > 0, 20,
                   "the play's first samples fused")
        proc.terminate()
        assert proc.wait(15) == 0
    with daemon_process(config, log2) as proc2, client_session(port) as session:
        wait_daemon_ready(session, proc2, log2)
        out, err = play.communicate(timeout=120)
    assert play.returncode == 1, (out, err)
    assert "restarted while this played" in err and "unaccounted" not in err, err
