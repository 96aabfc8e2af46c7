// x86 variant of kernel gather (../gather.cl), for TSTEP 8 on CPU devices whose OpenCL
// compiler is clang: it needs clang's ext_vector_type and uses AVX-512BW builtins where the
// target has them. It is not portable OpenCL C, so it is never the default: the host appends
// it to gather.cl (whose helpers and integer contract it shares, with STACK_SIGNED=1) only
// on a device where the self-test built it and found every pixel equal to the numpy reference.
//
// A work-item renders one run of 64 pixels (192 RGB bytes) on BANDS bands of 8 rows, a band being
// the rows that share one pair of map rows (rows 8k - 4 .. 8k + 3). Runs start at multiples
// of 8 pixels (see x0 below), so the map intervals a run covers, and each lane's place inside
// its interval (kx), are the same for every run. Per band the ten map columns of the next map
// row are read and faded once (the band above read the other row), the frames the 8 rows
// need are bounded by the samples' extremes (u is monotone in them): lo .. lo + span + 1, and
// H - 255 lo of both map rows comes per lane from shuffles and one multiply in 16-bit lanes
// (map_row). Per row a lane's 16 u + 8 (relative to 255 lo) grows by a constant,
// 2 (H_bot - H_top), in 16-bit lanes, and u gives its frame (lo + u / 255) and its weight
// (u % 255) at once: the header's integers. When the run's source is linear (inside one
// cell, or two cells split at a boundary; a per-pixel map must be linear with one tone) and
// a band's frames lie within lo .. lo + MAX_SPAN + 1, the band is blended and toned in 16-bit
// lanes on 64-byte vectors: three chunks of 64 bytes, each byte's frames merged bytewise and
// its weight found by a shuffle. The rows go in segments that share their sources (the rows
// of one cell row, across bands, or one row of a per-pixel map): each chunk's source offsets
// and tone factors are set up once per segment, so a row only loads frames, blends, tones and
// stores. Any other band goes pixel by pixel with the same integers. A run's 192 RGB bytes
// go out in the output's pixel format (PIXEL_BYTES 3, or 4: four 64-byte chunks shuffled from
// the three, alpha set). (Clang's ext_vector_type
// gives the 64-wide types OpenCL C lacks: on AVX-512 one operation covers 32 or 64 lanes,
// where a float16 covers 16.)
typedef uchar  u8x64  __attribute__((ext_vector_type(64)));
typedef char   i8x64  __attribute__((ext_vector_type(64)));
typedef ushort u16x64 __attribute__((ext_vector_type(64)));
typedef ushort u16x32 __attribute__((ext_vector_type(32)));
typedef short  i16x64 __attribute__((ext_vector_type(64)));
typedef short  i16x32 __attribute__((ext_vector_type(32)));
typedef uint   u32x64 __attribute__((ext_vector_type(64)));
typedef int    i32x64 __attribute__((ext_vector_type(64)));
typedef int    i32x32 __attribute__((ext_vector_type(32)));
typedef u8x64 __attribute__((aligned(1))) u8x64_u;
typedef i16x32 __attribute__((aligned(2))) i16x32_u;
typedef int16 __attribute__((aligned(4))) int16_u;
typedef float16 __attribute__((aligned(4))) float16_u;
#define LOAD64(p) (*(__global const u8x64_u *)(p))
#define LOADT(p) (*(__global const i16x32_u *)(p))
// comparisons give signed lanes (0 or -1); these reinterpret them as masks
#define AS_U8(x) __builtin_astype((x), u8x64)
#define AS_I16(x) __builtin_astype((x), i16x32)
// lanes where m is all ones take b, the others a
#define PICK(m, a, b) (((a) & ~(m)) | ((b) & (m)))
#define MAX_SPAN 5   // a fast run blends frames lo .. lo + MAX_SPAN + 1 at most

#define IOTA32 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31
#define IOTA32H 32, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59, 60, 61, 62, 63
#define IOTA64 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40, 41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54, 55, 56, 57, 58, 59, 60, 61, 62, 63
#define KLO 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 5, 5, 5, 5, 5, 6, 6, 6, 6, 6, 6, 6, 6, 7, 7, 7, 7, 7, 7, 7, 7, 8, 8, 8, 8
#define KHI 1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 5, 5, 5, 5, 5, 6, 6, 6, 6, 6, 6, 6, 6, 7, 7, 7, 7, 7, 7, 7, 7, 8, 8, 8, 8, 8, 8, 8, 8, 9, 9, 9, 9
#define KX64 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7, 9, 11, 13, 15, 1, 3, 5, 7
#define PIX0 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5, 5, 5, 6, 6, 6, 7, 7, 7, 8, 8, 8, 9, 9, 9, 10, 10, 10, 11, 11, 11, 12, 12, 12, 13, 13, 13, 14, 14, 14, 15, 15, 15, 16, 16, 16, 17, 17, 17, 18, 18, 18, 19, 19, 19, 20, 20, 20, 21
#define PIX1 21, 21, 22, 22, 22, 23, 23, 23, 24, 24, 24, 25, 25, 25, 26, 26, 26, 27, 27, 27, 28, 28, 28, 29, 29, 29, 30, 30, 30, 31, 31, 31, 32, 32, 32, 33, 33, 33, 34, 34, 34, 35, 35, 35, 36, 36, 36, 37, 37, 37, 38, 38, 38, 39, 39, 39, 40, 40, 40, 41, 41, 41, 42, 42
#define PIX2 42, 43, 43, 43, 44, 44, 44, 45, 45, 45, 46, 46, 46, 47, 47, 47, 48, 48, 48, 49, 49, 49, 50, 50, 50, 51, 51, 51, 52, 52, 52, 53, 53, 53, 54, 54, 54, 55, 55, 55, 56, 56, 56, 57, 57, 57, 58, 58, 58, 59, 59, 59, 60, 60, 60, 61, 61, 61, 62, 62, 62, 63, 63, 63
// A chunk's 64 bytes in the word order of the byte interleave (x86 unpack: within each
// 16-byte lane, bytes 0-7 go to the low half, 8-15 to the high half): the bytes each 16-bit
// lane holds (BYTE_*), the interleave of two chunks (UNPACK_*), and the pixel of each lane
// for chunk C of a run (W*C: lane -> (64 C + byte) / 3).
#define BYTE_LO 0, 1, 2, 3, 4, 5, 6, 7, 16, 17, 18, 19, 20, 21, 22, 23, 32, 33, 34, 35, 36, 37, 38, 39, 48, 49, 50, 51, 52, 53, 54, 55
#define BYTE_HI 8, 9, 10, 11, 12, 13, 14, 15, 24, 25, 26, 27, 28, 29, 30, 31, 40, 41, 42, 43, 44, 45, 46, 47, 56, 57, 58, 59, 60, 61, 62, 63
#define UNPACK_LO 0, 64, 1, 65, 2, 66, 3, 67, 4, 68, 5, 69, 6, 70, 7, 71, 16, 80, 17, 81, 18, 82, 19, 83, 20, 84, 21, 85, 22, 86, 23, 87, 32, 96, 33, 97, 34, 98, 35, 99, 36, 100, 37, 101, 38, 102, 39, 103, 48, 112, 49, 113, 50, 114, 51, 115, 52, 116, 53, 117, 54, 118, 55, 119
#define UNPACK_HI 8, 72, 9, 73, 10, 74, 11, 75, 12, 76, 13, 77, 14, 78, 15, 79, 24, 88, 25, 89, 26, 90, 27, 91, 28, 92, 29, 93, 30, 94, 31, 95, 40, 104, 41, 105, 42, 106, 43, 107, 44, 108, 45, 109, 46, 110, 47, 111, 56, 120, 57, 121, 58, 122, 59, 123, 60, 124, 61, 125, 62, 126, 63, 127
#define WLO0 0, 0, 0, 1, 1, 1, 2, 2, 5, 5, 6, 6, 6, 7, 7, 7, 10, 11, 11, 11, 12, 12, 12, 13, 16, 16, 16, 17, 17, 17, 18, 18
#define WHI0 2, 3, 3, 3, 4, 4, 4, 5, 8, 8, 8, 9, 9, 9, 10, 10, 13, 13, 14, 14, 14, 15, 15, 15, 18, 19, 19, 19, 20, 20, 20, 21
#define WLO1 21, 21, 22, 22, 22, 23, 23, 23, 26, 27, 27, 27, 28, 28, 28, 29, 32, 32, 32, 33, 33, 33, 34, 34, 37, 37, 38, 38, 38, 39, 39, 39
#define WHI1 24, 24, 24, 25, 25, 25, 26, 26, 29, 29, 30, 30, 30, 31, 31, 31, 34, 35, 35, 35, 36, 36, 36, 37, 40, 40, 40, 41, 41, 41, 42, 42
#define WLO2 42, 43, 43, 43, 44, 44, 44, 45, 48, 48, 48, 49, 49, 49, 50, 50, 53, 53, 54, 54, 54, 55, 55, 55, 58, 59, 59, 59, 60, 60, 60, 61
#define WHI2 45, 45, 46, 46, 46, 47, 47, 47, 50, 51, 51, 51, 52, 52, 52, 53, 56, 56, 56, 57, 57, 57, 58, 58, 61, 61, 62, 62, 62, 63, 63, 63
#define EVEN32 0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30, 32, 34, 36, 38, 40, 42, 44, 46, 48, 50, 52, 54, 56, 58, 60, 62
#define ODD32 1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31, 33, 35, 37, 39, 41, 43, 45, 47, 49, 51, 53, 55, 57, 59, 61, 63
#define PACK64 0, 1, 2, 3, 4, 5, 6, 7, 32, 33, 34, 35, 36, 37, 38, 39, 8, 9, 10, 11, 12, 13, 14, 15, 40, 41, 42, 43, 44, 45, 46, 47, 16, 17, 18, 19, 20, 21, 22, 23, 48, 49, 50, 51, 52, 53, 54, 55, 24, 25, 26, 27, 28, 29, 30, 31, 56, 57, 58, 59, 60, 61, 62, 63

// A run's bytes in a 4-byte format: chunk Q of the output (pixels 16 Q .. 16 Q + 15) is a
// shuffle of the RGB chunks (c0, c0), (c0, c1), (c1, c2) or (c2, c2) (those bytes start at
// RGB byte 0, 0, 64, 128), each pixel's colours placed at R_AT, G_AT, B_AT; alpha lanes take
// any byte and are then set to 255.
#define CSEL(s) ((s) == R_AT ? 0 : (s) == G_AT ? 1 : (s) == B_AT ? 2 : 0)
#define PX(Q, j, b) (3 * (16 * (Q) + (j) / 4) + CSEL((j) % 4) - (b))
#define PX4(Q, j, b) PX(Q, j, b), PX(Q, j + 1, b), PX(Q, j + 2, b), PX(Q, j + 3, b)
#define PX16(Q, j, b) PX4(Q, j, b), PX4(Q, j + 4, b), PX4(Q, j + 8, b), PX4(Q, j + 12, b)
#define PX64(Q, b) PX16(Q, 0, b), PX16(Q, 16, b), PX16(Q, 32, b), PX16(Q, 48, b)
#define AL4(j) ((j) == A_AT ? 255 : 0), ((j) + 1 == A_AT ? 255 : 0), ((j) + 2 == A_AT ? 255 : 0), ((j) + 3 == A_AT ? 255 : 0)
#define AL16 AL4(0), AL4(0), AL4(0), AL4(0)
#define AL64 AL16, AL16, AL16, AL16

// X86_BW: the compiler targets AVX-512BW and the x86 builtins below are used (PORTABLE=1, a
// define for tests, takes the plain vector code instead, which computes the same lanes)
#ifndef PORTABLE
#define PORTABLE 0
#endif
#if defined(__AVX512BW__) && !PORTABLE
#define X86_BW 1
#else
#define X86_BW 0
#endif

// u8 x s8 pairs summed into s16 lanes (x86 pmaddubsw; no lane here saturates), and two s16
// vectors narrowed with unsigned saturation in the x86 pack order (packuswb): the
// instructions where the compiler targets AVX-512BW, the same lanes in plain vector code elsewhere
#if X86_BW
#define MADDUBS(w, x) __builtin_ia32_pmaddubsw512(__builtin_astype((w), i8x64), __builtin_astype((x), i8x64))
#define PACKUS(lo, hi) __builtin_astype(__builtin_ia32_packuswb512((lo), (hi)), u8x64)
#else
inline i16x32 maddubs(u8x64 w, i8x64 x)
{
    return __builtin_convertvector(__builtin_shufflevector(w, w, EVEN32), i16x32)
         * __builtin_convertvector(__builtin_shufflevector(x, x, EVEN32), i16x32)
         + __builtin_convertvector(__builtin_shufflevector(w, w, ODD32), i16x32)
         * __builtin_convertvector(__builtin_shufflevector(x, x, ODD32), i16x32);
}
inline u8x64 packus(i16x32 lo, i16x32 hi)
{
    const i16x64 v = __builtin_shufflevector(lo, hi, PACK64);
    return __builtin_convertvector(v < (short)0 ? (i16x64)0 : v > (short)255 ? (i16x64)255 : v, u8x64);
}
#define MADDUBS(w, x) maddubs(__builtin_astype((w), u8x64), __builtin_astype((x), i8x64))
#define PACKUS(lo, hi) packus((lo), (hi))
#endif

// floor of 16 floats (exact for |v| < 2^31)
inline int16 floor16(float16 v)
{
    const int16 i = convert_int16(v);
    return i + (convert_float16(i) > v);                 // a true comparison is -1
}

// (a b) >> 16 in unsigned 16-bit lanes (pmulhuw)
#if X86_BW
typedef short v32hi __attribute__((vector_size(64)));
inline u16x64 mulhu(u16x64 a, u16x64 b)
{
    const v32hi alo = __builtin_astype(__builtin_shufflevector(a, a, IOTA32), v32hi);
    const v32hi ahi = __builtin_astype(__builtin_shufflevector(a, a, IOTA32H), v32hi);
    const v32hi blo = __builtin_astype(__builtin_shufflevector(b, b, IOTA32), v32hi);
    const v32hi bhi = __builtin_astype(__builtin_shufflevector(b, b, IOTA32H), v32hi);
    return __builtin_shufflevector(__builtin_astype(__builtin_ia32_pmulhuw512(alo, blo), u16x32),
                                   __builtin_astype(__builtin_ia32_pmulhuw512(ahi, bhi), u16x32), IOTA64);
}
#define MULHU(a, b) mulhu((a), (b))
#else
#define MULHU(a, b) __builtin_convertvector((__builtin_convertvector((a), u32x64) * __builtin_convertvector((b), u32x64)) >> 16, u16x64)
#endif

// H - 255 lo of one map row in each lane, from its ten samples relative to 4080 lo (r, in 16
// bits when the run's frames lie within MAX_SPAN + 1 of lo). With A, B the lane's samples and
// kx its place: floor((A (16 - kx) + B kx + 128) / 256) = (A + 8 + floor((B - A) kx / 16)) >> 4
// (A + 8 is whole), and floor(d kx / 16) = pmulhuw(d + 32768, kx 2^12) - 2048 kx. The sums
// wrap modulo 2^16; the result fits.
inline i16x64 map_row(ushort16 r)
{
    const u16x64 a = __builtin_shufflevector(r, r, KLO), b = __builtin_shufflevector(r, r, KHI);
    const u16x64 kx = (u16x64)(KX64);
    return __builtin_astype(a + MULHU(b - a + (ushort)32768, kx << 12) + ((ushort)8 - (kx << 11)), i16x64) >> 4;
}
// (v g) >> 16 in 16-bit lanes (pmulhw; the builtin, or the compiler keeps g widened to 32 bits)
#if X86_BW
#define MULHI(v, g) __builtin_astype(__builtin_ia32_pmulhw512(__builtin_astype((v), v32hi), __builtin_astype((g), v32hi)), i16x32)
#else
#define MULHI(v, g) __builtin_convertvector((__builtin_convertvector((v), i32x32) * __builtin_convertvector((g), i32x32)) >> 16, i16x32)
#endif

// One 64-byte chunk C (0..2) of a fast run on the row `r` bytes below the segment's first,
// as a value: pick each byte's frames, blend, tone. The stack holds bytes v ^ 0x80 (SVAL), so
// a byte read as signed is v - 128; the blend is one pmaddubsw per 32 lanes: (v_a - 128,
// v_b - 128) interleaved against the lane's weight pair (255 - w, w). The chunk's sources
// (oa##C, ob##C, mixed##C, mb##C) and tone (gl##C .. oh##C) are the segment's (see the kernel).
#define CHUNK(C)                                                                                          \
    ({                                                                                                    \
        const long o0 = oa##C + r, o1 = ob##C + r;                                                        \
        u8x64 fa = LOAD64(stack + fo[0] + o0), fb = LOAD64(stack + fo[1] + o0);                           \
        if (mixed##C) {                                                                                   \
            fa = PICK(mb##C, fa, LOAD64(stack + fo[0] + o1));                                             \
            fb = PICK(mb##C, fb, LOAD64(stack + fo[1] + o1));                                             \
        }                                                                                                 \
        if (span > 0) {                  /* lanes at frame lo + k take the pair (k, k + 1) */             \
            const u8x64 sc = __builtin_shufflevector(s8, s8, PIX##C);                                     \
            u8x64 prev = fb;                                                                              \
            for (int k = 1; k <= span; ++k) {                                                             \
                u8x64 fn = LOAD64(stack + fo[k + 1] + o0);                                                \
                if (mixed##C)                                                                             \
                    fn = PICK(mb##C, fn, LOAD64(stack + fo[k + 1] + o1));                                 \
                const u8x64 mk = AS_U8(sc >= (uchar)k);                                                   \
                fa = PICK(mk, fa, prev);                                                                  \
                fb = PICK(mk, fb, fn);                                                                    \
                prev = fn;                                                                                \
            }                                                                                             \
        }                                                                                                 \
        const i16x32 vl = MADDUBS(__builtin_shufflevector(pw, pw, WLO##C), __builtin_shufflevector(fa, fb, UNPACK_LO)); \
        const i16x32 vh = MADDUBS(__builtin_shufflevector(pw, pw, WHI##C), __builtin_shufflevector(fa, fb, UNPACK_HI)); \
        PACKUS((MULHI(vl, gl##C) + ol##C) >> 1, (MULHI(vh, gh##C) + oh##C) >> 1);                         \
    })

// A run's bytes of chunk C before `from` come from the first cell, the rest from the second; a
// chunk with both mixes them bytewise (mb). Declares the chunk's segment sources and tone too.
#define CHUNK_SPLIT(C)                                                                                    \
    const int from##C = 3 * split - 64 * C;                                                               \
    const bool mixed##C = from##C > 0 && from##C < 64;                                                    \
    const u8x64 mb##C = AS_U8(iota8 >= (char)from##C);                                                    \
    long oa##C = 0, ob##C = 0;                                                                            \
    i16x32 gl##C = 0, gh##C = 0, ol##C = 0, oh##C = 0;

// A segment's sources (pa, pb) and tones for chunk C, the tone mixed like the bytes.
#define CHUNK_SETUP(C)                                                                                    \
    {                                                                                                     \
        oa##C = (from##C <= 0 ? pb : pa) + 64 * C;                                                        \
        ob##C = pb + 64 * C;                                                                              \
        __global const short *tc = from##C <= 0 ? tnb : tn;                                               \
        gl##C = LOADT(tc + 64 * C);                                                                       \
        gh##C = LOADT(tc + 64 * C + 32);                                                                  \
        ol##C = LOADT(tc + TONE_OB + 64 * C);                                                             \
        oh##C = LOADT(tc + TONE_OB + 64 * C + 32);                                                        \
        if (mixed##C && toneb != tone) {                                                                  \
            const i16x32 ml = AS_I16(byte_lo >= (short)from##C), mh = AS_I16(byte_hi >= (short)from##C);  \
            gl##C = PICK(ml, gl##C, LOADT(tnb + 64 * C));                                                 \
            gh##C = PICK(mh, gh##C, LOADT(tnb + 64 * C + 32));                                            \
            ol##C = PICK(ml, ol##C, LOADT(tnb + TONE_OB + 64 * C));                                       \
            oh##C = PICK(mh, oh##C, LOADT(tnb + TONE_OB + 64 * C + 32));                                  \
        }                                                                                                 \
    }

// the faded map samples j0 .. j0 + 9 of map row `row` in lanes 0-9, in 4080ths past base (lanes
// 10-15 are padding: the columns after them, or sample 9 again at the map's edges)
inline int16 map_samples(__global const float *tmap, __global const float *tmap1, float fade, float f0,
                         int tmap_w, size_t row, int j0)
{
    float16 a;
    if (j0 >= 0 && j0 + 9 < tmap_w) {            // one load each (the maps are padded by 16 floats)
        const float16 a0 = *(__global const float16_u *)(tmap + row + j0), a1 = *(__global const float16_u *)(tmap1 + row + j0);
        a = a0 + fade * (a1 - a0);
    } else {
        float ta[16];
        for (int j = 0; j < 16; ++j)
            ta[j] = faded(tmap, tmap1, fade, row + clamp(j0 + min(j, 9), 0, tmap_w - 1));
        a = vload16(0, ta);
    }
    return floor16((f0 + a) * 4080.0f + 0.5f);
}

// A full run's bytes go out with non-temporal 64-byte stores where they are 64-byte
// aligned (the runs are placed so, see the kernel): such a store skips reading the line it
// fills (a plain store reads it first: twice the memory traffic) and leaves the caches to
// the frame stack.
#define NT_STORE(p, v) __builtin_nontemporal_store((v), (__global u8x64 *)(p))

__kernel void gather_wide(GATHER_PARAMS)
{
    stack += STACK_PAD;
    const int base = fast_floor(t0);
    const float f0 = t0 - (float)base;
    const i8x64 iota8 = (i8x64)(IOTA64);
    const i16x32 byte_lo = (i16x32)(BYTE_LO), byte_hi = (i16x32)(BYTE_HI);
    // Runs start at x0 + 64 k: with rows a multiple of 64 bytes long and out 16, 32 or 48
    // bytes off 64, x0 (16, 32 or 48 pixels) puts every run on 64-byte boundaries (3 x0 = -out
    // mod 64; 43 = 1/3 mod 64); a head run k = -1 renders pixels 0 .. 63 and keeps x0 of them.
    // x0 is a multiple of 8, so the map intervals of every run are still alike.
    // In a 4-byte format (a run is 256 bytes) only 32 bytes off 64 can be made up (x0 = 8).
    const int mis = (int)((size_t)out & 63);
#if PIXEL_BYTES == 3
    const int x0 = (width * 3) % 64 == 0 && mis % 16 == 0 ? (43 * (64 - mis)) & 63 : 0;
#else
    const int x0 = (width * PIXEL_BYTES) % 64 == 0 && mis % 32 == 0 ? ((64 - mis) & 63) / 4 : 0;
#endif
    const int k = (int)get_global_id(0) - (x0 > 0);
    const int xs = max(x0 + 64 * k, 0);
    if (xs >= width)
        return;
    const int nvalid = k < 0 ? x0 : min(64, width - xs);   // pixels of the run to store
    const int j0 = (xs >> 3) - 1;                         // the run's map columns j0 .. j0 + 9
#if GRID
    const int cx = xs / CELL_W;
    const int edge = (cx + 1) * CELL_W;               // the next cell's first pixel
    const int split = edge < xs + nvalid ? edge - xs : 64;
    // else a third cell in the run: per pixel
    const bool lin_src = split == 64 || edge + CELL_W >= xs + nvalid;
    int cur_cy = -1, seg_y = 0;                       // the segment's cell row and first row
#else
    const int split = 64;
#endif
    CHUNK_SPLIT(0)
    CHUNK_SPLIT(1)
    CHUNK_SPLIT(2)
    const int yi0 = (int)get_global_id(1) * BANDS - 1;
    int16 qnext = map_samples(tmap, tmap1, fade, f0, tmap_w, (size_t)clamp(yi0, 0, tmap_h - 1) * tmap_w, j0);
    for (int yi = yi0; yi < yi0 + BANDS; ++yi) {          // the bands: map rows yi, yi + 1
        const int ybeg = max(8 * yi + 4, 0), yend = min(8 * yi + 12, height);
        if (ybeg >= yend)
            break;
        const int ky0 = 2 * (ybeg - 8 * yi) - 7;                      // the first row's ky (header)
        const int16 qa = qnext, qb = map_samples(tmap, tmap1, fade, f0, tmap_w, (size_t)clamp(yi + 1, 0, tmap_h - 1) * tmap_w, j0);
        qnext = qb;                                     // the next band's upper map row
        // the extremes of both rows' samples 0-9 (lanes 10-15 made copies of lane 9) bound every u
        const uint16 to9 = (uint16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 9, 9, 9, 9);
        const int16 a9 = shuffle(qa, to9), b9 = shuffle(qb, to9);
        const int16 m16 = min(a9, b9), x16 = max(a9, b9);
        const int8 m8 = min(m16.lo, m16.hi), x8 = max(x16.lo, x16.hi);
        const int4 m4 = min(m8.lo, m8.hi), x4 = max(x8.lo, x8.hi);
        const int2 m2 = min(m4.lo, m4.hi), x2 = max(x4.lo, x4.hi);
        // frames base + lo .. base + lo + span (+1 to blend): u is monotone in the samples
        const int lo = floor_div((min(m2.lo, m2.hi) + 8) >> 4, 255);
        const int span = floor_div((max(x2.lo, x2.hi) + 8) >> 4, 255) - lo;
        // along x, H - 255 lo of both map rows per lane; per row, 16 u + 8 relative to 255 lo:
        // v = 16 ht + ky (hb - ht) + 8, ky += 2 a row (fits 16 bits when span <= MAX_SPAN)
        const i16x64 ht = map_row(convert_ushort16(qa - 4080 * lo)), hb = map_row(convert_ushort16(qb - 4080 * lo));
        const i16x64 drb = hb - ht, d16 = drb + drb;
        i16x64 v16 = __builtin_astype(__builtin_astype(ht, u16x64) * (ushort)16 + __builtin_astype(drb, u16x64) * (ushort)ky0 + (ushort)8, i16x64);
        // byte offsets of the frames base + lo .. base + lo + span + 1
        long fo[MAX_SPAN + 2];
#if WRAP == WRAP_LOOP
        for (int i = 0, f = wrap_index(base + lo); i < min(span, MAX_SPAN) + 2; ++i, f = f + 1 < NFRAMES ? f + 1 : 0)
            fo[i] = f * ((long)FRAME_PIXELS * 3);
#else
        for (int i = 0; i < min(span, MAX_SPAN) + 2; ++i)
            fo[i] = wrap_index(base + lo + i) * ((long)FRAME_PIXELS * 3);
#endif
        // The rows go in segments that share their sources: the rows of one cell row (GRID,
        // set up when the cell row changes), or one row (a per-pixel map).
        for (int y = ybeg; y < yend;) {
#if GRID
            const bool linear = span <= MAX_SPAN && lin_src;
            const int cy = y / CELL_H, yseg = min(yend, (cy + 1) * CELL_H);
            __global const int *srow = source + cy * grid_w;
            if (cy != cur_cy) {
                const int dy = (y - cy * CELL_H) * FRAME_W;
                const int packed = srow[cx];
                const int tone = (packed >> 24) & 0xFF;
                const long pa = (long)((packed & 0xFFFFFF) + dy + (xs - cx * CELL_W)) * 3;
                int toneb = tone;
                long pb = 0;                              // may lie before the stack: inside STACK_PAD
                if (split < 64) {                         // lanes >= split read pixb + lane
                    const int next = srow[cx + 1];
                    pb = (long)((next & 0xFFFFFF) + dy - split) * 3;
                    toneb = (next >> 24) & 0xFF;
                }
                __global const short *tn = tones + tone * TONE_STRIDE, *tnb = tones + toneb * TONE_STRIDE;
                CHUNK_SETUP(0)
                CHUNK_SETUP(1)
                CHUNK_SETUP(2)
                cur_cy = cy;
                seg_y = y;
            }
#else
            const int yseg = y + 1, seg_y = y;
            __global const int *srow = source + (size_t)y * width;
            bool linear = span <= MAX_SPAN && nvalid == 64;
            if (linear) {
                const int16 step = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
                const int first = srow[xs];
                for (int i = 0; i < 4; ++i)
                    linear = linear && all(*(__global const int16_u *)(srow + xs + 16 * i) - first == step + 16 * i);
                const int tone = (first >> 24) & 0xFF, toneb = tone;
                const long pa = (long)(first & 0xFFFFFF) * 3, pb = 0;
                __global const short *tn = tones + tone * TONE_STRIDE, *tnb = tn;
                CHUNK_SETUP(0)
                CHUNK_SETUP(1)
                CHUNK_SETUP(2)
            }
#endif
            if (linear) {
                long r = (long)(y - seg_y) * (3 * FRAME_W);
                for (; y < yseg; ++y, v16 += d16, r += 3 * FRAME_W) {
                    __global uchar *p = out + ((size_t)y * width + xs) * PIXEL_BYTES;
                    // u = 255 frame (above lo) + weight, within 255 (span + 1)
                    const u16x64 u16 = __builtin_astype(v16 >> 4, u16x64);
                    // frame u / 255 (exact for u < 65535 with the +1), weight u % 255, and the lane's
                    // weight pair (255 - w, w) as one little-endian word: 255 (w + 1)
                    // (one frame pair, span 0: k = 0 everywhere)
                    u16x64 k16 = (u16x64)0;
                    u8x64 s8 = (u8x64)0;
                    if (span > 0) {
                        k16 = MULHU(u16 + (ushort)1, (u16x64)257);
                        s8 = __builtin_convertvector(k16, u8x64);
                    }
#if INTERP
                    const u16x64 pw = (u16 - k16 * (ushort)255 + (ushort)1) * (ushort)255;
#else
                    const u16x64 pw = (u16x64)255;
#endif
                    const u8x64 c0 = CHUNK(0), c1 = CHUNK(1), c2 = CHUNK(2);
#if PIXEL_BYTES == 3
                    const u8x64 run[3] = {c0, c1, c2};
#else
                    const u8x64 alpha = (u8x64)(AL64);
                    const u8x64 run[4] = {__builtin_shufflevector(c0, c0, PX64(0, 0)) | alpha,
                                          __builtin_shufflevector(c0, c1, PX64(1, 0)) | alpha,
                                          __builtin_shufflevector(c1, c2, PX64(2, 64)) | alpha,
                                          __builtin_shufflevector(c2, c2, PX64(3, 128)) | alpha};
#endif
                    if (nvalid == 64 && ((size_t)p & 63) == 0) {
                        for (int c = 0; c < PIXEL_BYTES; ++c)
                            NT_STORE(p + 64 * c, run[c]);
                    } else if (nvalid == 64) {
                        for (int c = 0; c < PIXEL_BYTES; ++c)
                            *(__global u8x64_u *)(p + 64 * c) = run[c];
                    } else {                                   // the head run, or a run past the row's end
                        uchar part[64 * PIXEL_BYTES];
                        for (int c = 0; c < PIXEL_BYTES; ++c)
                            *(u8x64_u *)(part + 64 * c) = run[c];
                        for (int i = 0; i < PIXEL_BYTES * nvalid; ++i)
                            p[i] = part[i];
                    }
                }
            } else {                                       // the same integers in 32 bits
#if GRID
                int ddy = (y - cy * CELL_H) * FRAME_W;
#else
                int ddy = 0;
#endif
                for (; y < yseg; ++y, v16 += d16, ddy += FRAME_W) {
                    __global uchar *orow = out + (size_t)y * width * PIXEL_BYTES;
                    const int ky = ky0 + 2 * (y - ybeg);
                    for (int q = 0; q < nvalid; ++q) {
                        const int x = xs + q;
                        int pk;
                        const int pix = source_pixel(srow, ddy, x, &pk);
                        const int j = (2 * q + 9) >> 4, kx = (2 * q + 9) & 15;   // the lane's map interval
                        const int top = ((qa[j] * (16 - kx) + qa[j + 1] * kx + 128) >> 8) - 255 * lo;
                        const int bot = ((qb[j] * (16 - kx) + qb[j + 1] * kx + 128) >> 8) - 255 * lo;
                        const int u = (16 * top + ky * (bot - top) + 8) >> 4;
                        pixel(stack, tones, pix, (pk >> 24) & 0xFF, base + lo + u / 255, u % 255, orow + PIXEL_BYTES * x);
                    }
                }
            }
        }
    }
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_sfence();       // the non-temporal stores land before the kernel is seen done
#endif
}

