"""A finished run's provenance.json records where it ran: the machine (its CPU, cores and instruction
sets), TensorFlow's version, build and thread settings, and the code's commit."""

import json
import os

import pytest
import tensorflow as tf


@pytest.mark.slow
def test_provenance_records_the_machine_and_tensorflows_build(finished):
    record = json.loads((finished / "provenance.json").read_text())
    assert record["machine"]["cpu"] and record["machine"]["cores"] == os.cpu_count()
    assert set(record["machine"]["isa"]) <= {"sse4_2", "avx", "avx2", "fma", "avx512f", "avx512_vnni", "amx_tile"}
    assert record["tensorflow"]["version"] == tf.__version__ and record["tensorflow"]["onednn"] == "0"
    assert record["tensorflow"]["intra_op_threads"] == 1 and "is_cuda_build" in record["tensorflow"]["build"]
    assert record["code_commit"] is None or len(record["code_commit"]) == 40
