"""Whether this machine can hold a plan, judged from its job count before any job is made.

A plan is built as columns: its keys (render, image, prediction: about 500 bytes a job as Python
strings and arrays) and a column per control parameter (about 360 bytes a job each). Measured as
``sweep3d plan``'s peak resident memory over 200,000 random-policy jobs: 1.2 KB a job with two
range parameters, 2.65 KB with six. A spec whose estimate is over the memory this machine has
available is refused in one line, before numpy's MemoryError (a 110-line traceback, or none at
all when there is no memory left to print it).
"""

from __future__ import annotations

from pathlib import Path

from sweep3d.spec import LoadedSpec

JOB_BYTES = 500
PARAMETER_BYTES = 360
MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")


def plan_bytes(jobs: int, parameters: int) -> int:
    """About how many bytes a plan of ``jobs`` jobs with ``parameters`` parameter columns takes."""
    return jobs * (JOB_BYTES + PARAMETER_BYTES * parameters)


def available_memory() -> int | None:
    """Bytes this process may still allocate: the system's available memory, or the container's
    (cgroup v2) limit less its use when lower; None where neither can be read."""
    found = [n for n in (_meminfo_available(), _cgroup_left()) if n is not None]
    return min(found) if found else None


def _meminfo_available() -> int | None:
    try:
        for line in MEMINFO.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_left() -> int | None:
    try:
        limit = (CGROUP / "memory.max").read_text().strip()
        used = int((CGROUP / "memory.current").read_text())
        return None if limit == "max" else int(limit) - used
    except (OSError, ValueError):
        return None


def check_memory(spec: LoadedSpec, jobs: int, knob: str) -> None:
    """Refuse a plan of ``jobs`` jobs whose estimated memory is over what the machine has available.

    Args:
        knob: what to lower (the policy's parameter that sets the count).

    Raises:
        SpecError: naming the jobs, the memory they need, what is available and what to lower.
    """
    needed = plan_bytes(jobs, len(spec.parameter_columns))
    available = available_memory()
    if available is None or needed <= available:
        return
    raise spec.fail("policy", f"the spec expands to {jobs:,} jobs, which need about {_gb(needed)} of memory to plan "
                              f"(about {needed // jobs:,} bytes a job), but this machine has {_gb(available)} "
                              f"available; lower {knob} (or the objects and environments), or split the sweep "
                              "into several specs")


def _gb(n: int) -> str:
    return f"{n / 1e9:,.1f} GB"

