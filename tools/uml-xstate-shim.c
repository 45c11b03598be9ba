/*
 * LD_PRELOAD shim for User-Mode Linux 6.1 (Debian bookworm's linux.uml) on hosts
 * whose XSAVE area is larger than UML's: CPUs with AVX-512 or AMX.
 *
 * UML saves and restores its processes' FPU state with
 * ptrace(PTRACE_{GET,SET}REGSET, NT_X86_XSTATE) through a buffer sized for
 * x87 + SSE + AVX (832 bytes).  GETREGSET with a short buffer is truncated,
 * but the host kernel refuses a SETREGSET whose size is not the host's whole
 * XSAVE area (EFAULT), so UML panics at its first process ("ptrace set fp
 * regs failed, errno = 14").  This shim passes such a SETREGSET on with the
 * whole area: the caller's bytes first (x87, SSE, AVX, and the header), the
 * rest as the tracee has it now.  The components beyond AVX (AVX-512, AMX)
 * are therefore not switched between threads of one UML process; tools/uml-init.sh
 * keeps glibc, numpy and OpenBLAS off AVX-512 inside UML for that reason.
 * Where the host's area is no larger than UML's, every call passes unchanged.
 *
 * Built and used by tools/vcan-tests.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#ifndef NT_X86_XSTATE
#define NT_X86_XSTATE 0x202
#endif
/* Legacy region (512) + XSAVE header (64): what every standard-format area starts with. */
#define XSAVE_HEADER_END 576
#define XSTATE_BV_OFFSET 512
/* x87, SSE and AVX: the components inside UML's own buffer. */
#define OWN_COMPONENTS 7u

typedef long (*ptrace_fn)(int, pid_t, void *, void *);

long ptrace(enum __ptrace_request request, ...)
{
	static ptrace_fn real;
	static __thread unsigned char whole[1 << 16] __attribute__((aligned(64)));
	va_list ap;
	pid_t pid;
	void *addr, *data;

	va_start(ap, request);
	pid = va_arg(ap, pid_t);
	addr = va_arg(ap, void *);
	data = va_arg(ap, void *);
	va_end(ap);
	if (!real)
		real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
	if (request == PTRACE_SETREGSET && (uintptr_t)addr == NT_X86_XSTATE && data) {
		struct iovec *own = data;
		struct iovec all = { whole, sizeof whole };

		if (own->iov_len >= XSAVE_HEADER_END && real(PTRACE_GETREGSET, pid, addr, &all) == 0 &&
		    all.iov_len > own->iov_len) {
			uint64_t bv_own, bv_host;

			memcpy(&bv_host, whole + XSTATE_BV_OFFSET, 8);
			memcpy(whole, own->iov_base, own->iov_len);
			memcpy(&bv_own, whole + XSTATE_BV_OFFSET, 8);
			bv_own = (bv_own & OWN_COMPONENTS) | (bv_host & ~(uint64_t)OWN_COMPONENTS);
			memcpy(whole + XSTATE_BV_OFFSET, &bv_own, 8);
			return real(PTRACE_SETREGSET, pid, addr, &all);
		}
	}
	return real(request, pid, addr, data);
}
