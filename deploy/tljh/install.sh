#!/usr/bin/env bash
# The Littlest JupyterHub on one machine (Ubuntu 22.04/24.04, as root), for a class using mexone:
#   bash deploy/tljh/install.sh ADMIN_NAME
# TLJH's own installer, with mexone installed into the users' environment (its --user-requirements-txt-url
# takes a URL; a pip command after the install does the same for this checkout).
set -euo pipefail
admin="${1:?usage: install.sh ADMIN_NAME}"
checkout="$(cd "$(dirname "$0")/../.." && pwd)"  # mexone is on no package index: from this clone
curl -L https://tljh.jupyter.org/bootstrap.py | sudo python3 - --admin "$admin" --show-progress-page
sudo -E /opt/tljh/user/bin/pip install "$checkout[hub]"
sudo tljh-config set services.cull.timeout 3600  # idle labs stop after an hour away
sudo tljh-config set limits.memory 1G            # per student: the lab and its Jupyter server fit
sudo tljh-config reload
