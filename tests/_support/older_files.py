"""Result files as an older flexvib wrote them (a test helper): tests that read an older format
make it from a file of this one by deleting what the older version did not write."""

from __future__ import annotations

from typing import Any

from studies._integrity import DIGEST, POINT_DIGEST, POINT_OUTPUTS  # the checksums' names: no public face


def as_format_2(handle: Any, *studies: str) -> None:
    """Make the open h5py file ``handle`` (mode "a") and its study groups ``studies`` result format 2:
    their ``format_version`` 2 and none of format 3's checksums (format 2 had none: the file's and
    each group's ``digest``, a grid study's ``point_digest`` dataset and ``point_outputs`` list).
    A format-2 file carrying format-3 checksums would be neither version's file."""
    for item in (handle, *(handle[name] for name in studies)):
        item.attrs["format_version"] = 2
        for name in (DIGEST, POINT_OUTPUTS):
            if name in item.attrs:
                del item.attrs[name]
        if POINT_DIGEST in item:
            del item[POINT_DIGEST]
