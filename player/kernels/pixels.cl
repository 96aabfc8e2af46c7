// RGB bytes placed as pixels of the output format, and unaligned vector stores: shared by the
// kernels that write any pixel format (built in front of each of them).
// Defines: PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (the byte of each channel in a pixel; A_AT -1: none).

// One RGB pixel as a pixel of the output format at o.
inline void put1(const uchar r, const uchar g, const uchar b, __global uchar *o)
{
    o[R_AT] = r;
    o[G_AT] = g;
    o[B_AT] = b;
#if A_AT >= 0
    o[A_AT] = 255;
#endif
}

// Under-aligned vector types: one unaligned store into any caller's array (PoCL's vstore16 of
// uchar stores byte by byte).
typedef uchar16 __attribute__((aligned(1))) uchar16_u;
typedef uint16 __attribute__((aligned(1))) uint16_u;

#if PIXEL_BYTES == 4

#define PLACE(v) ((((v) & 0xFFu) << (8 * R_AT)) | ((((v) >> 8) & 0xFFu) << (8 * G_AT)) | \
                  ((((v) >> 16) & 0xFFu) << (8 * B_AT)) | (0xFFu << (8 * A_AT)))

// 16 RGB pixels (48 bytes in c0, c1, c2) as 16 four-byte pixels at p.
inline void put16(uchar16 c0, uchar16 c1, uchar16 c2, __global uchar *p)
{
#ifdef __ENDIAN_LITTLE__
    const uint16 w = (uint16)(as_uint4(c0), as_uint4(c1), as_uint4(c2), (uint4)(0));
    // pixel k starts at RGB byte 3k: word 3k / 4, bit 8 * (3k % 4); its last bytes spill into the next word
    const uint16 lo = w.s00123345667899ab, hi = w.s112344567789aabc;
    const uint16 s = (uint16)(0, 24, 16, 8, 0, 24, 16, 8, 0, 24, 16, 8, 0, 24, 16, 8);
    const uint16 v = (lo >> s) | ((hi << 1) << (31 - s));  // (hi << 1) << 31 is 0 where s is 0
    *(__global uint16_u *)p = PLACE(v);
#else
    uchar rgb[48];
    vstore16(c0, 0, rgb); vstore16(c1, 1, rgb); vstore16(c2, 2, rgb);
    for (int k = 0; k < 16; ++k)
        put1(rgb[3 * k], rgb[3 * k + 1], rgb[3 * k + 2], p + 4 * k);
#endif
}

#endif
