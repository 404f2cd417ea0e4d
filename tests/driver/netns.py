"""A private network namespace for the tests that talk UDP multicast (issue 27, item 6).

``udpm://`` URLs are used ONLY inside a namespace made here: ``unshare -n`` (as root, as
developers and CI run) gives a network stack with a loopback interface alone, which
is brought up with multicast routed to it. Nothing leaves the namespace, not even an
IGMP report: the script checks that ``lo`` is its only interface before anything else.
Where a namespace cannot be made the tests are skipped with the reason, except under
``NSDRAKE_REQUIRE_NAMESPACE=1`` (CI, .ci/run), where they fail.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

URL = "udpm://239.255.76.67:7667?ttl=0"
SETUP = (
    '[ "$(ip -o link show | wc -l)" = 1 ] || { echo "not a private network namespace" >&2; exit 97; }\n'
    "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo\n"
)


def namespace_unavailable() -> str | None:
    """Why a private network namespace cannot be made here (None: it can)."""
    missing = [tool for tool in ("unshare", "ip") if shutil.which(tool) is None]
    if missing:
        return f"no {' or '.join(missing)} command (util-linux, iproute2)"
    result = subprocess.run(
        ["unshare", "-n", "--fork", "--kill-child", "bash", "-c", SETUP], capture_output=True, text=True
    )
    if result.returncode:
        return f"cannot make a private network namespace (unshare -n needs root): {result.stderr.strip()}"
    return None


def require_namespace() -> None:
    reason = namespace_unavailable()
    if reason is None:
        return
    if os.environ.get("NSDRAKE_REQUIRE_NAMESPACE") == "1":
        pytest.fail(f"NSDRAKE_REQUIRE_NAMESPACE=1 but {reason}")
    pytest.skip(reason)


def run_in_namespace(script: str, *, cwd, timeout: float) -> subprocess.CompletedProcess:
    """``script`` (bash) in a fresh private network namespace, after SETUP."""
    return subprocess.run(
        ["unshare", "-n", "--fork", "--kill-child", "bash", "-c", f"set -e\n{SETUP}set +e\n{script}"],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
