"""The SIMD features of this CPU that its operating system has enabled (baseline build).

GCC's and Clang's ``__builtin_cpu_supports`` read cpuid and check with xgetbv
that the OS saves the wide registers, as Embree's ``getCPUFeatures`` does.
"""
cdef extern from *:
    """
    static int rs_cpu_has(int which)
    {
    #if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
        __builtin_cpu_init();
        switch (which) {
        case 0: return __builtin_cpu_supports("sse2");
        case 1: return __builtin_cpu_supports("avx2");
        case 2: return __builtin_cpu_supports("avx512f");
        case 3: return __builtin_cpu_supports("avx512vl");
        case 4: return __builtin_cpu_supports("avx512bw");
        case 5: return __builtin_cpu_supports("avx512dq");
        case 6: return __builtin_cpu_supports("fma");
        }
    #elif defined(_M_X64)
        return which == 0;    /* MSVC: SSE2 is the x64 baseline; wider ISAs not probed */
    #endif
        return 0;
    }
    """
    int rs_cpu_has(int which) nogil

FEATURES = ("sse2", "avx2", "avx512f", "avx512vl", "avx512bw", "avx512dq", "fma")


def features():
    """The names in FEATURES this CPU and OS support (empty off x86)."""
    return [name for i, name in enumerate(FEATURES) if rs_cpu_has(i)]
