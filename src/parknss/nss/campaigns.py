"""Where the NSS commands get their data: a campaign folder, or the default campaign.

Without ``--data`` the commands use the default campaign: the bundled folder
(``campaigns/default``) if the checkout has one, else the synthetic reference campaign
``generate_campaign(seed=0)``, which is deterministic and therefore cached under
``.cache/`` (keyed by the generator version and the vehicle parameters) after the first
generation.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

from parknss.config import BUNDLED_CAMPAIGN, REPO_ROOT
from parknss.data.trial import Campaign

CACHE_DIR = REPO_ROOT / ".cache"


def _cache_path(seed: int) -> Path:
    from parknss.reference.campaign import GENERATOR_VERSION
    from parknss.reference.params import load_vehicle_params

    digest = load_vehicle_params(None).digest()
    return CACHE_DIR / f"campaign_seed{seed}_v{GENERATOR_VERSION}_{digest}"


def default_campaign(seed: int = 0) -> Campaign:
    """The bundled campaign, or the cached/generated synthetic one."""
    from parknss.data.io import read_campaign, write_campaign

    if (BUNDLED_CAMPAIGN / "campaign.json").is_file():
        return read_campaign(BUNDLED_CAMPAIGN)
    path = _cache_path(seed)
    if (path / "campaign.json").is_file():
        return read_campaign(path)
    from parknss.reference.campaign import generate_campaign

    print(f"generating the default synthetic campaign (seed {seed}) ...", file=sys.stderr)
    campaign = generate_campaign(seed=seed)
    with contextlib.suppress(OSError):  # a read-only checkout: use it from memory
        write_campaign(campaign, path, overwrite=True)  # a cache: replace a partial one
    return campaign


def campaign_label(command: str, data: str | Path | None) -> str:
    """How messages name a command and its campaign: ``"parknss train --data DIR"``."""
    return f"{command} --data {data}" if data is not None else f"{command} (default campaign)"


def load_campaign(
    data: str | Path | None, workflow: str | None = None, command: str = "parknss"
) -> Campaign:
    """``data`` folder if given, else :func:`default_campaign`.

    With ``workflow`` (a key of :data:`parknss.data.workflows.WORKFLOWS`), a campaign that
    lacks a channel the workflow needs, or whose trials differ in their channels, is
    refused with one DataError line naming ``command``, the campaign and the channels.
    """
    if data is None:
        campaign = default_campaign()
    else:
        from parknss.data.io import read_campaign

        campaign = read_campaign(data)
    if workflow is not None:
        from parknss.data.workflows import require

        require(campaign, workflow, campaign_label(command, data))
    return campaign
