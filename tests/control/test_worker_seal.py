"""Sealing a controller's shared memory (control/worker.py): Linux refuses F_SEAL_WRITE with
EBUSY while the file is held writable (a shared writable mapping, or a page still pinned after
a write); that passes, so the seal is tried again rather than the lab's start failing on
"OSError: [Errno 16] Device or resource busy" (once in a graded run, issue 36)."""

from __future__ import annotations

import mmap
import os
import threading

import pytest

from mexone.control import worker

if not hasattr(os, "memfd_create"):
    pytest.skip("memfd and its seals are Linux's", allow_module_level=True)

import fcntl  # noqa: E402 - Linux's seals, after the skip

WRITE = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SEAL


def _held_writable() -> tuple[int, mmap.mmap]:
    fd = os.memfd_create("mexone-test", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    os.ftruncate(fd, 4096)
    return fd, mmap.mmap(fd, 4096, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)


def test_a_seal_refused_while_the_file_is_held_is_tried_again_until_it_is_let_go():
    fd, mapping = _held_writable()
    try:
        with pytest.raises(OSError) as refused:  # what the kernel says, at once
            fcntl.fcntl(fd, fcntl.F_ADD_SEALS, WRITE)
        assert refused.value.errno == 16 and refused.value.filename is None
        threading.Timer(0.02, mapping.close).start()  # let go while the seal waits
        worker._seal(fd, WRITE)
        assert fcntl.fcntl(fd, fcntl.F_GET_SEALS) & fcntl.F_SEAL_WRITE
    finally:
        os.close(fd)


def test_a_seal_still_refused_after_its_tries_says_so():
    fd, mapping = _held_writable()
    try:
        with pytest.raises(OSError, match="Device or resource busy"):
            worker._seal(fd, WRITE)
    finally:
        mapping.close()
        os.close(fd)


def test_the_model_block_is_sealed_against_writes():
    import mujoco

    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><body><freejoint/><geom size='.1'/>"
                                           "</body></worldbody></mujoco>")
    fd, size = worker.model_block(model)
    try:
        assert size == mujoco.mj_sizeModel(model)
        assert fcntl.fcntl(fd, fcntl.F_GET_SEALS) & fcntl.F_SEAL_WRITE
        with pytest.raises(PermissionError):
            os.write(fd, b"x")
    finally:
        os.close(fd)

