"""OpenBLAS's kernel is pinned where results are compared bit for bit (``scenarios.blas``)."""

from __future__ import annotations

import os
import platform

import pytest

from scenarios.blas import PINNED_CORETYPE, VARIABLE, pin_blas_kernel

X86 = platform.machine().lower() in ("x86_64", "amd64")


@pytest.mark.skipif(not X86, reason="OpenBLAS's core types are x86's")
def test_the_pin_sets_the_kernel_unless_the_user_chose_one():
    env: dict[str, str] = {}
    assert pin_blas_kernel(env) and env[VARIABLE] == PINNED_CORETYPE
    chosen = {VARIABLE: "Zen"}
    assert not pin_blas_kernel(chosen) and chosen[VARIABLE] == "Zen"  # the user's choice stands, and is said to differ


@pytest.mark.skipif(not X86, reason="OpenBLAS's core types are x86's")
def test_the_tests_run_on_the_pinned_kernel():
    assert os.environ.get(VARIABLE) == PINNED_CORETYPE  # tests/conftest.py, before numpy loaded OpenBLAS
