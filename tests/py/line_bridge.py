#!/usr/bin/env python3
"""An instrument bridged to volcal's `line` backend (protocol: volcal_nodes::backend::line).
Here a stand-in for a vendor SDK: readings grow 10 mm per point along each beam; every reply is
logged (--log) so that a test can find it in the bag. Usage: line_bridge.py PORT [--log FILE]"""
import socketserver, sys, threading

LOG = open(sys.argv[3], "w") if len(sys.argv) > 3 else None
lock = threading.Lock()

class Bridge(socketserver.StreamRequestHandler):
    def handle(self):
        beam = (0, 0)
        for line in self.rfile:
            w = line.decode().split()
            if w == ["INFO?"]:
                reply = "INFO wavelength_vac_m=6.329912e-7 compensated=1 instrument=bridge-demo"
            elif w[0] == "BEAM":
                beam, reply = (int(w[1]), int(w[2])), "OK"
            elif w[0] == "READ" and w[2] != "-":  # a triggered reading: SDK call goes here
                value = 0.3 + 0.01 * int(w[2]) + 1e-6 * beam[1]
                reply = f"R {value!r} 0.9"
                with lock:
                    LOG and (LOG.write(f"{beam[0]},{beam[1]},{w[2]},{value!r}\n"), LOG.flush())
            elif w == ["ENV?"]:
                reply = "ENV air_temp_c=20.1 air_pressure_pa=101000 air_rh_pct=45 machine_temp_c=20.05"
            else:
                reply = "ERR unknown request " + " ".join(w)
            self.wfile.write((reply + "\n").encode())

socketserver.ThreadingTCPServer.allow_reuse_address = True
server = socketserver.ThreadingTCPServer(("127.0.0.1", int(sys.argv[1])), Bridge)
print(server.server_address[1], flush=True)  # the port (PORT 0: any free one)
server.serve_forever()
