"""Kernel receive stamps: the time bytes reached the socket, not the time they were read."""

from __future__ import annotations

import io
import socket
import time

from services.sim.arrival import StampedReader
from tests.conftest import wait_for


def test_the_stamp_is_when_the_bytes_arrived_not_when_they_were_read() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    client = socket.create_connection(server.getsockname())
    conn, _ = server.accept()
    try:
        reader = io.BufferedReader(StampedReader(conn))
        # The kernel turns receive stamping on shortly after the first socket asks for it
        # (a deferred switch), so the first segments may come unstamped: until one is.
        def warmed_up() -> bool:
            client.sendall(b"warm-up\r\n")
            assert reader.readline() == b"warm-up\r\n"
            return bool(reader.raw.stamped)

        wait_for(warmed_up, timeout=5, period=0.01)
        sent = []
        for line in (b"GET /a HTTP/1.1\r\n", b"GET /b HTTP/1.1\r\n", b"GET /c HTTP/1.1\r\n"):
            sent.append(time.time())
            client.sendall(line)
            time.sleep(0.1)  # the reader comes late, as a busy server thread would
            assert reader.readline() == line
            read = time.time()
            arrived = reader.raw.arrived_s
            assert sent[-1] - 0.001 <= arrived <= sent[-1] + 0.02, (sent[-1], arrived)
            assert read - arrived > 0.09
    finally:
        for sock in (client, conn, server):
            sock.close()
