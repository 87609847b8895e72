"""What ``sweep3d realism`` keeps in the store: the ``verdicts`` table and the photographs it
scored (its rows' kept files), declared once, here; and where ``realism pick`` puts a kit.

A verdict's key is what it is of (source, experiment, job, model), so scoring again writes a
newer row of the same key, which counts ("newest"). The store knows the table only by this
contract (the package root names this module, so every command sees the table): ``cache
verify`` decodes each photo a verdict names, ``cache gc`` removes those none names, ``cache
stats`` counts them.
"""

from __future__ import annotations

from pathlib import Path

from sweep3d.cache import KeptFiles, TableContract, register_table
from sweep3d.results import PHOTOS_FOLDER, VERDICTS

#: Where ``realism pick`` writes an experiment's kit by default (``kits/<experiment>``): the one
#: folder of the store that is the user's to read and add photographs to, not a run's.
KITS_FOLDER = "kits"
#: Columns every verdicts segment has had since the table was first written.
COLUMNS = ("verdict_key", "source", "experiment", "job", "model", "valid", "correct", "created_at")


def photo_damage(path: Path) -> str:
    """Why the kept photo at ``path`` does not decode ("" when it does); raises FileNotFoundError
    when it is not there. Its bytes are a re-encoded thumbnail, so no digest of them is recorded."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            im.load()
    except FileNotFoundError:
        raise
    except (OSError, ValueError, Image.DecompressionBombError) as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        return first.replace(f"'{path}'", "").replace(str(path), path.name).strip()
    return ""


PHOTOS = KeptFiles(folder=PHOTOS_FOLDER, column="photo_sha256", suffix=".jpg", noun="photo", check=photo_damage,
                   missing_fix="run sweep3d realism score again to keep it", unnamed="no verdict names")
VERDICTS_TABLE = register_table(TableContract(VERDICTS, key="verdict_key", columns=COLUMNS, merge="newest",
                                              kept=PHOTOS))
