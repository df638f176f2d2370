"""`--scheduler` pointed at a server that is not a Dask scheduler: the one-line error
says so, instead of the reason numpy gives for the frame length it read from the reply
(`Unable to allocate 3.07 EiB ...`)."""
import socket
import threading

import pytest

from gripper_sim.workflows.study import StudyError, open_client

HTTP_REPLY = b'HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n' * 4


@pytest.fixture
def http_port():
    """A port on 127.0.0.1 whose server answers every connection as an HTTP server."""
    server = socket.socket()
    server.bind(('127.0.0.1', 0))
    server.listen()
    stop = threading.Event()

    def serve():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                connection, _ = server.accept()
            except OSError:
                continue
            with connection:
                connection.sendall(HTTP_REPLY)
                connection.settimeout(1.0)
                try:
                    connection.recv(1024)
                except OSError:
                    pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[1]
    stop.set()
    thread.join(timeout=5)
    server.close()


def test_a_server_that_is_not_a_dask_scheduler_is_named_as_such(http_port):
    address = f'tcp://127.0.0.1:{http_port}'
    with pytest.raises(StudyError, match='not as a Dask scheduler') as caught:
        with open_client(address):
            pass
    message = str(caught.value)
    assert message.startswith(f'cannot reach the Dask scheduler at {address} (')
    assert 'allocate' not in message
    assert '\n' not in message


def test_a_malformed_address_keeps_its_own_reason():
    with pytest.raises(StudyError, match="unknown address scheme 'foo'"):
        with open_client('foo://127.0.0.1:1'):
            pass
