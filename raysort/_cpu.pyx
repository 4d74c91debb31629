"""Which SIMD path was compiled, and what this CPU supports."""
cdef extern from "raysort/simd.h":
    const char *rs_simd_name()

cdef extern from *:
    """
    static int rs_cpu_has(int which)
    {
    #if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
        __builtin_cpu_init();
        switch (which) {
        case 0: return __builtin_cpu_supports("sse2");
        case 1: return __builtin_cpu_supports("sse4.1");
        case 2: return __builtin_cpu_supports("avx");
        case 3: return __builtin_cpu_supports("avx2");
        case 4: return __builtin_cpu_supports("avx512f");
        }
    #endif
        return 0;
    }
    """
    int rs_cpu_has(int which)

FEATURES = ("sse2", "sse4.1", "avx", "avx2", "avx512f")


def compiled_path():
    """"sse2" or "scalar": the path raysort/simd.h was built with."""
    return rs_simd_name().decode()


def cpu_features():
    """The SIMD features this CPU reports (empty off x86)."""
    return [name for i, name in enumerate(FEATURES) if rs_cpu_has(i)]
