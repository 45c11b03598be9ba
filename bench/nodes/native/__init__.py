"""The native node loop (issue 29): a node's per-period loop in C.

A node's whole per-period loop is to run in C, without Python or the GIL:
wait, receive, check E2E, decode, step, encode, send.  This folder holds
that loop's parts and the controller node's loop on the controller core, as
a small C library (no allocation after the open and init calls) and a test
program:

- ``bn.h``: the one header (frames, transports, clock, counters).
- ``bn_bus.c``: the transports.  SocketCAN raw sockets, classic and CAN FD
  (``CAN_RAW_FD_FRAMES``), for vcan and real adapters; python-can's
  ``udp_multicast`` bus (the default transport of a host without CAN): the
  same multicast group, port and ``SO_REUSEADDR``/``SO_REUSEPORT`` as
  python-can, so C and python-can nodes meet on one port; sent with hop limit
  0 (``BN_UDP_HOPS``, the bench's ``UDP_HOP_LIMIT``: every socket of the group on this host gets each
  datagram, no network device sends it).  Non-blocking
  receive up to an absolute deadline (``bn_recv_until``), the socket drained
  by ``recvmmsg``; send, and an instant's frames in one ``sendmmsg``
  (``bn_send_many``), from a socket of its own whose datagrams the
  receiving socket's filter drops (the kernel's loop-back copies).
- ``bn_msgpack.c``: python-can's udp_multicast datagram, the msgpack map of
  ``can/interfaces/udp_multicast/utils.py`` (eleven keys), written and read
  without allocation.
- ``bn_clock.c``: absolute ``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)``
  periods with an optional busy-wait tail, missed deadlines, late wake-ups,
  host stalls, busy time per period (median); ``bn_rt_apply``: SCHED_FIFO,
  ``mlockall``, CPU pin, with what was granted.  The counters are one struct
  (``bn_stats_t``) that Python reads with ctypes (:class:`._native.Stats`).
- ``bn_plant.h``, ``bn_plant.c``, ``bn_plant_loop.c``: the plant node's
  per-period logic on the plant core (transport-free: frames in, frames out)
  and its loop on a bus, lockstep and real time (each real-time period's
  send, receive and step time kept for Python beside its busy time); built and driven by
  :mod:`._plant_native` (``--engine native``).
- ``bn_ctl.h``, ``bn_ctl.c``: the controller node's per-period logic
  (:class:`bench.nodes._controller_node.ControllerNode` on frames in and
  out, no transport: ``bn_ctl_on_frame``) and its loop on a bus
  (``bn_ctl_serve``), stepping the controller core Python built (its
  ``cc_foc_t`` and ``cc_sup_t`` by address) and applying the pending bench
  commands at their step (``bn_ctl_apply_commands``); ``controller_node.py``:
  the Python side (set-up, the bench commands' queue, the report) and ``bench
  controller --engine native``.
- ``bn_pair.h``, ``bn_pair.c``: the in-process native pair: the plant unit and
  the controller unit stepped together for many periods per call, the frames
  passed in memory and the bench commands fed from a schedule made once
  (:func:`bench.nodes._loops.run_inprocess`'s loop); driven by :mod:`._pair`.
- ``bn_rec.h``, ``bn_rec.c``: the native recorder: a receive thread of its own
  (``SCHED_FIFO`` when asked) that keeps every udp_multicast datagram of a run's
  bus, with its kernel time stamp, in a ring allocated at open; Python takes the
  ring in batches (:mod:`._recorder_native`, :class:`bench.runs._recorder.Recording`).
- ``echo.c``: answers each PhaseSamples with a PwmDuty (same step, E2E CRC),
  or pings (round-trip times): the transports, the codec and the E2E check
  end to end, from python-can or from itself.

The frames are packed and unpacked with the C code ``bench codegen`` writes
from ``dbc/bench.dbc`` (cantools, :mod:`bench.wire._ccodec`) and protected
with its E2E helper (:func:`bench.cli.codegen.generate_e2e`); firmware/ uses
the same two.  :func:`._native.build` generates them and compiles the one
library (``libbench_native.so``: every unit above, the plant core and the
controller core) and the programs with the system's C compiler;
:func:`._native.library` builds it once per source change into the user's
cache and loads it once per process for every user.  ``bn.h`` holds what the
units share (``bn_frame_t``, ``bn_sig_t``), mirrored once in
:mod:`._native` (``Frame``, ``Sig``).

What is left for the loop of issue 29:

- the lockstep latency model in the in-process pair (such runs take the
  Python loop);
- the plant faults, sensor noise and load profiles in the plant core, so the
  native plant serves the runs that have them (today: the Python node, with
  a line saying why);
- the recorder on SocketCAN (python-can's reader serves there).
"""
