"""The Ray engine's errors without Ray: a cluster address nobody answers, a task that died."""

from __future__ import annotations

import socket

import pytest

from scenariomax.pipeline import ConversionError, check_ray_address, ray_failure


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_an_address_nobody_answers_fails_at_once_in_one_line():
    port = _free_port()  # closed again: nothing listens there
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        with pytest.raises(ConversionError, match=r"no Ray cluster answers there .*ray start --head") as error:
            check_ray_address(address, timeout_s=2.0)
        assert "\n" not in str(error.value) and address in str(error.value)


def test_a_listening_address_and_rays_own_words_pass():
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        check_ray_address(f"127.0.0.1:{server.getsockname()[1]}")
    for address in (None, "", "auto", "local"):
        check_ray_address(address)


@pytest.mark.parametrize("address", ["headnode", "headnode:port", ":6379"])
def test_a_malformed_address_is_named(address):
    with pytest.raises(ConversionError, match="expected HOST:PORT"):
        check_ray_address(address)


def test_a_failed_task_names_its_input_and_the_way_on():
    class WorkerCrashedError(Exception):  # stands in for ray.exceptions.WorkerCrashedError
        pass

    error = ray_failure("womd/training.tfrecord-00007", WorkerCrashedError("The worker died unexpectedly.\n  trace"))
    message = str(error)
    assert "\n" not in message and "womd/training.tfrecord-00007" in message
    assert "WorkerCrashedError: The worker died unexpectedly." in message and "--resume" in message
