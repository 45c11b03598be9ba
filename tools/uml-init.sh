# Body of the init script (PID 1) that tools/vcan-tests boots User-Mode Linux with.
#
# tools/vcan-tests prepends `#!/bin/bash`, the run's variables and the environment:
#   WORK         host directory of this run (logs, exit status, tmpfs mount point)
#   ROOT         the checkout
#   MODULES      CAN modules to load, in order, relative to the UML module tree
#   PYTEST_ARGS  array: -m socketcan plus the caller's arguments
# The root file system is the host's / (hostfs), so every path is the host's.
# Results for the host: $WORK/started, $WORK/setup.log, $WORK/setup-failed (why the
# setup failed), $WORK/pytest.log and $WORK/rc (pytest's exit status; the exit
# status of linux.uml itself says nothing about the tests).

PATH=$PATH:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
exec >"$WORK/setup.log" 2>&1 </dev/null
echo started >"$WORK/started"

halt_machine() {
	sync
	poweroff -f
	echo o >/proc/sysrq-trigger
	sleep 5
}

fail() {
	echo "setup failed: $*"
	echo "$*" >"$WORK/setup-failed"
	halt_machine
	exit 1
}

# File systems: /dev is devtmpfs (mounted by the kernel); /dev/shm is needed by
# multiprocessing's semaphores; temporary files live in a tmpfs, not on hostfs.
mount -t proc proc /proc || fail "mount -t proc"
mount -t sysfs sys /sys || fail "mount -t sysfs"
mountpoint -q /dev || mount -t devtmpfs dev /dev || fail "mount -t devtmpfs"
mkdir -p /dev/shm /dev/pts || fail "mkdir /dev/shm /dev/pts"
mount -t tmpfs -o mode=1777 shm /dev/shm || fail "mount tmpfs on /dev/shm"
mount -t devpts -o gid=5,mode=620,ptmxmode=666 devpts /dev/pts || fail "mount -t devpts"
mount -t tmpfs -o mode=1777 tmp "$WORK/tmp" || fail "mount tmpfs on $WORK/tmp"
export TMPDIR=$WORK/tmp
# No AVX-512 in the tests' processes: on a host with AVX-512 or AMX, UML switches
# only the x87/SSE/AVX state between the threads of one process (see
# tools/uml-xstate-shim.c), so glibc's string functions, numpy's kernels and
# OpenBLAS are kept to AVX2, whose state UML does switch.
export GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX512F,-AVX512VL,-AVX512BW,-AVX512CD,-AVX512DQ
export NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"
export OPENBLAS_CORETYPE=Haswell

# SocketCAN: the CAN core, raw and broadcast-manager sockets, then can-dev and vcan.
M=/usr/lib/uml/modules/$(uname -r)/kernel
for m in $MODULES; do
	insmod "$M/$m.ko" || fail "insmod $M/$m.ko"
done
for dev in vcan0 vcan1; do
	ip link add dev "$dev" type vcan || fail "ip link add dev $dev type vcan"
	ip link set "$dev" mtu 72 || fail "ip link set $dev mtu 72 (CAN FD)"
	ip link set up "$dev" || fail "ip link set up $dev"
done

# Loopback with IPv4 multicast (UDP multicast between processes).
ip link set lo up multicast on || fail "ip link set lo up"
ip route add 224.0.0.0/4 dev lo || fail "ip route add 224.0.0.0/4 dev lo"
# IPv6 multicast (python-can's udp_multicast default group) does not loop back on
# lo; a dummy device with multicast carries the route.  Optional.
if insmod "$M/lib/crc-ccitt.ko" && insmod "$M/net/ipv6/ipv6.ko" &&
	insmod "$M/drivers/net/dummy.ko" numdummies=0 &&
	ip link add mcast0 type dummy && ip link set mcast0 up multicast on &&
	ip -6 route add ff00::/8 dev mcast0 &&
	ip -6 route add multicast ff00::/8 dev mcast0 table local; then
	echo "IPv6 multicast via mcast0"
else
	echo "note: no IPv6 multicast inside User-Mode Linux"
fi
ip -brief link
echo "setup done"

cd "$ROOT" || fail "cd $ROOT"
"$ROOT/.venv/bin/pytest" "${PYTEST_ARGS[@]}" >"$WORK/pytest.log" 2>&1
rc=$?
# The temporary tree is a tmpfs that goes with the machine: keep the run folders
# of a failed run (their error.txt, node logs and reports) on the host.
if [ "$rc" -ne 0 ]; then
	mkdir -p "$WORK/kept" && cp -a "$WORK/tmp"/pytest-of-* "$WORK/kept/" 2>/dev/null
fi
echo "$rc" >"$WORK/rc.part" && mv "$WORK/rc.part" "$WORK/rc"
halt_machine
