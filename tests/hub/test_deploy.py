"""The class recipes in deploy/: what can be checked without a Kubernetes cluster or a fresh
Ubuntu machine. The Helm values load and size a student as benchmarks/RESULTS.md measured; the
image installs exactly what CI installs into the students' venv of the class test."""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

import yaml

from .classroom import PACKAGES

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"


def _pip_targets(line: str) -> list[str]:
    words = shlex.split(line.split("pip install", 1)[1].split("&&")[0])
    return sorted(re.sub(r"^.*?(\[[a-z,]+\])$", r"mexone\1", w) if "[" in w else w
                  for w in words if not w.startswith("-"))


def test_the_image_installs_what_ci_installs_for_the_class_test():
    docker = (DEPLOY / "zero-to-jupyterhub" / "Dockerfile").read_text()
    (image_line,) = [line for line in docker.splitlines() if "pip install" in line]
    assert _pip_targets(image_line) == sorted(PACKAGES) == ["jupyterhub", "mexone[hub]"]


def test_the_helm_values_size_a_student_and_cull_idle_labs():
    values = yaml.safe_load((DEPLOY / "zero-to-jupyterhub" / "config.yaml").read_text())
    user = values["singleuser"]
    assert user["defaultUrl"] == "/lab"
    assert 0.1 <= user["cpu"]["guarantee"] <= user["cpu"]["limit"]
    assert user["memory"]["guarantee"] in ("512M",) and user["memory"]["limit"] == "1G"
    assert values["cull"]["enabled"] and values["cull"]["timeout"] > 0
    assert set(values) <= {"singleuser", "cull", "hub", "proxy", "scheduling", "prePuller"}


def test_the_tljh_script_is_valid_bash_installing_mexone_in_the_users_environment():
    script = DEPLOY / "tljh" / "install.sh"
    subprocess.run(["bash", "-n", str(script)], check=True)
    text = script.read_text()
    # mexone is on no package index: the teacher's clone (the script's own), with the hub extra
    assert '/opt/tljh/user/bin/pip install "$checkout[hub]"' in text
    assert 'checkout="$(cd "$(dirname "$0")/../.." && pwd)"' in text
    assert "services.cull.timeout" in text
