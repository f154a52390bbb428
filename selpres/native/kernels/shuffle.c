/* selpres native shuffles: the per-epoch presentation orders of many replicas (selpres_shuffle), the same
 * permutations as selpres.sampler.epoch_orders computes in numpy, without a comparison sort.
 *
 * Built by selpres/native/build.py and bound by selpres/native/shuffle.py (load_shuffle) with the kernel's flags, no macros.
 *
 * Replica r's shuffle of its current set (the first `size` entries of its priority order) is the argsort
 * of h_i = mix(base_r + i * golden), i < size, base_r = mix(key_r ^ mix(epoch + golden)), where mix is splitmix64's finaliser: a bijection, so the
 * h_i are distinct and the argsort is one permutation, whatever algorithm finds it. Here: a counting sort
 * into 2^b buckets by the top b bits of h (2^b >= 2 size, so at most about one hash a bucket), which leaves every
 * hash at most a bucket away from its place, then an insertion sort by the full 64 bits that moves each
 * hash only past the few others of its bucket. Expected O(size) per replica instead of O(size log size).
 * With AVX-512DQ the hashes are computed 8 at a time (the same bits); the insertion skips, without
 * writing, every hash already after its predecessor (most of them).
 */
#include <immintrin.h>
#include <stdint.h>
#include <stdlib.h>

#define GOLDEN 0x9E3779B97F4A7C15ULL

static inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

#ifdef __AVX512DQ__
/* mix64 of 8 counters at once (integer arithmetic: the same bits as mix64 on each) */
static inline __m512i mix64x8(__m512i z)
{
    z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 30)), _mm512_set1_epi64(0xBF58476D1CE4E5B9ULL));
    z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64(z, 27)), _mm512_set1_epi64(0x94D049BB133111EBULL));
    return _mm512_xor_si512(z, _mm512_srli_epi64(z, 31));
}
#endif

/* h[i] = mix64(z + i * golden) for i < size */
static void hashes(uint64_t z, int64_t size, uint64_t *h)
{
    int64_t i = 0;
#ifdef __AVX512DQ__
    __m512i zv = _mm512_add_epi64(_mm512_set1_epi64((long long)z),
                                  _mm512_mullo_epi64(_mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0),
                                                     _mm512_set1_epi64((long long)GOLDEN)));
    const __m512i step = _mm512_set1_epi64((long long)(8 * GOLDEN));
    for (; i + 8 <= size; i += 8, zv = _mm512_add_epi64(zv, step)) _mm512_storeu_si512(h + i, mix64x8(zv));
#endif
    for (z += (uint64_t)i * GOLDEN; i < size; i++, z += GOLDEN) h[i] = mix64(z);
}

/* Replicas r0 .. r1-1: out[r * count + k] = orders[r][perm_r[k]] for k < count, perm_r the argsort of
   replica r's hashes over positions 0 .. size-1, whose base is mix(key[r] ^ mix(epoch[r] + golden)) (as
   selpres.sampler._shuffle_bases). Returns 0, or -1 (out of memory). */
int selpres_shuffle(int64_t r0, int64_t r1, const uint64_t *key, const uint64_t *epoch, const int64_t *const *orders,
                    int64_t size, int64_t count, int64_t *out)
{
    int bits = 1;
    while (bits < 62 && ((int64_t)1 << bits) < 2 * size) bits++; /* 2^b >= 2 size: fewer shared buckets */
    const int64_t nb = (int64_t)1 << bits;
    uint64_t *h = (uint64_t *)malloc((size_t)size * sizeof *h), *hs = (uint64_t *)malloc((size_t)size * sizeof *hs);
    int32_t *perm = (int32_t *)malloc((size_t)size * sizeof *perm);
    int32_t *start = (int32_t *)malloc((size_t)(nb + 1) * sizeof *start);
    if (!h || !hs || !perm || !start || size > INT32_MAX) {
        free(h);
        free(hs);
        free(perm);
        free(start);
        return -1;
    }
    for (int64_t r = r0; r < r1; r++) {
        for (int64_t b = 0; b <= nb; b++) start[b] = 0;
        hashes(mix64(key[r] ^ mix64(epoch[r] + GOLDEN)), size, h);  /* 8 at a time with AVX-512DQ */
        for (int64_t i = 0; i < size; i++) start[(h[i] >> (64 - bits)) + 1]++;
        for (int64_t b = 0; b < nb; b++) start[b + 1] += start[b];
        for (int64_t i = 0; i < size; i++) { /* placed with their hashes: the insertion reads no h[perm[.]] */
            const int32_t at = start[h[i] >> (64 - bits)]++;
            perm[at] = (int32_t)i;
            hs[at] = h[i];
        }
        for (int64_t k = 1; k < size; k++) { /* buckets are in order: only neighbours within one move */
            const uint64_t hp = hs[k];
            if (hs[k - 1] <= hp) continue; /* in place already, as most are: no writes */
            const int32_t p = perm[k];
            int64_t j = k;
            while (j > 0 && hs[j - 1] > hp) {
                perm[j] = perm[j - 1];
                hs[j] = hs[j - 1];
                j--;
            }
            perm[j] = p;
            hs[j] = hp;
        }
        const int64_t *ord = orders[r];
        int64_t *o = out + r * count;
        /* streaming stores: the orders (8 MB at R = 1000) go to memory without first being read into the
           cache, which made two threads no faster than one (the writes' bandwidth was the limit) */
        for (int64_t k = 0; k < count; k++) _mm_stream_si64((long long *)&o[k], (long long)ord[perm[k]]);
    }
    _mm_sfence(); /* the streamed orders are visible before the caller is told they are done */
    free(h);
    free(hs);
    free(perm);
    free(start);
    return 0;
}
