// Unaligned vector stores and RGB bytes placed as four-byte pixels: shared by the kernels that
// keep RGB stacks and write any pixel format (built in front of blend.cl and runs.cl).
// Defines: PIXEL_BYTES, R_AT, G_AT, B_AT, A_AT (the byte of each channel in a four-byte pixel).

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
    for (int k = 0; k < 16; ++k) {
        p[4 * k + R_AT] = rgb[3 * k]; p[4 * k + G_AT] = rgb[3 * k + 1]; p[4 * k + B_AT] = rgb[3 * k + 2];
        p[4 * k + A_AT] = 255;
    }
#endif
}

#endif
