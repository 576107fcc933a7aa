"""A reader on the link: every frame that reaches this host's interface, whoever it is for, appended
raw to a file until SIGTERM. Run inside a host (network namespace) of tests/hosts/netns.py:

    python -m tests.hosts.sniff IFACE OUT
"""

import signal
import socket
import sys

ETH_P_ALL = 0x0003


def main(interface: str, out: str) -> None:
    capture = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
    capture.bind((interface, 0))
    capture.settimeout(0.2)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    with open(out, "wb") as file:
        print("capturing", flush=True)
        while not stop:
            try:
                file.write(capture.recv(65535))
            except TimeoutError:
                continue


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
