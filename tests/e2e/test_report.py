"""The replay HTML report, rendered by a real browser (headless Chromium) when one is installed."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars"]


@pytest.fixture(scope="module")
def report(jackal_bag, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report")
    proc = subprocess.run([sys.executable, "-m", "fusiond", "replay", str(jackal_bag), "--config",
                           "examples/jackal_rl.toml", "--report", str(out), "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    return out


def test_report_has_the_plots_and_the_doctor(report):
    page = (report / "index.html").read_text()
    for img in ("overview.png", "innovations.png"):
        assert f'src="{img}"' in page
        data = (report / img).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert 'id="verdicts"' in page
    # the robot_localization-alike config predicts heading from skid-steer wheels that the gyro and the
    # IMU's own yaw contradict: the doctor blames the wheels (not the IMU) and says to fuse the gyro
    assert "wheel/heading" in page and "sensors.imu.angular_velocity" in page and "angular_velocity = true" in page
    assert "whole run" in page


@pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (Debian package chromium)")
def test_report_renders_in_headless_chromium_with_its_images(report, tmp_path):
    import matplotlib.image as mpimg

    shot = tmp_path / "shot.png"
    profile = tmp_path / "profile"
    subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--window-size=1280,2400",
                    f"--screenshot={shot}", (report / "index.html").as_uri()],
                   capture_output=True, timeout=120, check=False)
    assert shot.is_file(), "chromium wrote no screenshot"
    img = mpimg.imread(shot)[:, :, :3]
    assert img.shape[0] >= 2000 and img.shape[1] >= 1200
    # the trajectory's blue line and the verdict table's coloured rows are on the page
    blue = (img[:, :, 2] > 0.6) & (img[:, :, 0] < 0.3) & (img[:, :, 1] < 0.6)
    assert blue.sum() > 500, "no plot pixels: the images did not load"
    assert np.std(img) > 0.05
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}-dom", "--dump-dom",
                          (report / "index.html").as_uri()], capture_output=True, text=True, timeout=120)
    assert 'id="verdicts"' in dom.stdout and '<tr class="problem">' in dom.stdout
