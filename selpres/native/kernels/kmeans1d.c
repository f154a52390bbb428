/* selpres native exact 1-D k-means (selpres_kmeans1d): the split points of an optimal partition of sorted
 * distinct values into G contiguous groups, the same ones as the numpy dynamic programme of
 * selpres.presentation.kmeans computes, in the same floating-point operations.
 *
 * Built by selpres/native/build.py and bound by selpres/native/kmeans.py (load_kmeans) with the kernels' flags and
 * -ffp-contract=off, no macros: no FMA replaces a multiply and an add, so every value is rounded as numpy rounds
 * it, and the same candidate wins every comparison. AVX-512 where the compiler targets it (eight candidates a
 * vector), else AVX2 (four): the same numbers either way.
 *
 * D_1(i) = Q_i - S_i^2 / W_i; D_k(i) = min_{k-1 <= j < i} D_{k-1}(j) + ((Q_i - Q_j) - (S_i - S_j)^2 / (W_i - W_j)),
 * the leftmost minimiser kept; W, S, Q: prefix sums of the weights w, of w x and of (w x) x, summed in order as
 * numpy's cumsum. Each layer by divide and conquer over i (task: a range of i and a range of j): the middle i is
 * solved over the j up to i - 1, then its left half searches j up to that minimiser and its right half from it.
 * The ranges do not depend on the order the tasks are solved in, so the result is numpy's (which solves one depth
 * at a time). Here: depth first while a task spans more than LEAF i's (a subtree's values then stay in cache),
 * breadth first below (the tasks of one depth are independent, so the processor overlaps their latencies). The
 * last layer needs D_G(d) only: just the chain of right halves that ends at i = d is solved, with the same ranges.
 *
 * Only the candidates' order of comparison differs from numpy: vector lanes each keep their leftmost least value
 * (strictly less replaces), then the least value of all and, among the lanes holding it, the least index: the
 * leftmost minimiser, as numpy's reduceat then its first index equal to it. Any candidate that is not finite
 * (overflow, NaN) hands the call back to numpy, whose rules for those are not copied here.
 */
#include <immintrin.h>
#include <math.h>
#include <stdint.h>

#define LEAF 4096 /* i's in a breadth-first subtree (measured: 1024 to 16384 alike, 256 or fewer slower) */

typedef struct {
    int64_t ilo, ihi, jlo, jhi;
} task;

typedef struct {
    const double *W, *S, *Q, *prev; /* prefix sums, and the previous layer's D */
    double *D;                      /* this layer's D */
    int64_t *arg;                   /* this layer's leftmost minimisers */
    task *buf;                      /* 2 LEAF tasks: a subtree's two depths */
    int bad;                        /* a candidate was not finite */
} layer_t;

#if defined(__AVX512F__)
/* The candidates j .. j+7 of the lanes in `in` (the others: 0 loaded, any finite value out) */
static inline __m512d values(const layer_t *L, __m512d vw, __m512d vs, __m512d vq, __mmask8 in, int64_t j)
{
    const __m512d ss = _mm512_sub_pd(vs, _mm512_maskz_loadu_pd(in, L->S + j));
    const __m512d ws = _mm512_sub_pd(vw, _mm512_maskz_loadu_pd(in, L->W + j));
    const __m512d q = _mm512_sub_pd(vq, _mm512_maskz_loadu_pd(in, L->Q + j));
    return _mm512_add_pd(_mm512_maskz_loadu_pd(in, L->prev + j), _mm512_sub_pd(q, _mm512_div_pd(_mm512_mul_pd(ss, ss), ws)));
}

/* The leftmost j in [lo, hi] minimising prev[j] + ((Q[m] - Q[j]) - (S[m] - S[j])^2 / (W[m] - W[j])); *best its
   value. Eight candidates a vector; a short range is one masked vector, whose lane order is index order. */
static inline int64_t argmin(layer_t *L, int64_t m, int64_t lo, int64_t hi, double *best)
{
    const __m512d vw = _mm512_set1_pd(L->W[m]), vs = _mm512_set1_pd(L->S[m]), vq = _mm512_set1_pd(L->Q[m]);
    const __m512d inf = _mm512_set1_pd(INFINITY);
    if (hi - lo < 8) {
        const __mmask8 in = (__mmask8)((1u << (hi + 1 - lo)) - 1);
        const __m512d v = _mm512_mask_mov_pd(inf, in, values(L, vw, vs, vq, in, lo));
        L->bad |= (_mm512_cmp_pd_mask(_mm512_abs_pd(v), inf, _CMP_LT_OQ) | (__mmask8)~in) != 0xFF;
        const double b = _mm512_reduce_min_pd(v);
        *best = b;
        return lo + __builtin_ctz((unsigned)_mm512_cmp_pd_mask(v, _mm512_set1_pd(b), _CMP_EQ_OQ) | 0x100u);
    }
    __m512d vb = inf;
    __m512i vi = _mm512_set1_epi64(INT64_MAX);
    __m512i idx = _mm512_add_epi64(_mm512_set1_epi64(lo), _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0));
    const __m512i eight = _mm512_set1_epi64(8);
    __mmask8 fin = 0xFF;
    int64_t j = lo;
    for (; j + 8 <= hi + 1; j += 8, idx = _mm512_add_epi64(idx, eight)) {
        const __m512d v = values(L, vw, vs, vq, 0xFF, j);
        fin &= _mm512_cmp_pd_mask(_mm512_abs_pd(v), inf, _CMP_LT_OQ);
        const __mmask8 lt = _mm512_cmp_pd_mask(v, vb, _CMP_LT_OQ); /* strictly: each lane keeps its leftmost */
        vb = _mm512_mask_mov_pd(vb, lt, v);
        vi = _mm512_mask_mov_epi64(vi, lt, idx);
    }
    if (j <= hi) { /* the rest: one masked vector */
        const __mmask8 in = (__mmask8)((1u << (hi + 1 - j)) - 1);
        const __m512d v = values(L, vw, vs, vq, in, j);
        fin &= _mm512_cmp_pd_mask(_mm512_abs_pd(v), inf, _CMP_LT_OQ) | (__mmask8)~in;
        const __mmask8 lt = _mm512_mask_cmp_pd_mask(in, v, vb, _CMP_LT_OQ);
        vb = _mm512_mask_mov_pd(vb, lt, v);
        vi = _mm512_mask_mov_epi64(vi, lt, idx);
    }
    L->bad |= fin != 0xFF;
    const double b = _mm512_reduce_min_pd(vb);
    *best = b;
    return _mm512_mask_reduce_min_epi64(_mm512_cmp_pd_mask(vb, _mm512_set1_pd(b), _CMP_EQ_OQ), vi);
}
#else
/* As above, four candidates a vector (AVX2; the lanes not in `in`: 0 loaded, any finite value out). */
static inline __m256d values(const layer_t *L, __m256d vw, __m256d vs, __m256d vq, __m256i in, int64_t j)
{
    const __m256d ss = _mm256_sub_pd(vs, _mm256_maskload_pd(L->S + j, in));
    const __m256d ws = _mm256_sub_pd(vw, _mm256_maskload_pd(L->W + j, in));
    const __m256d q = _mm256_sub_pd(vq, _mm256_maskload_pd(L->Q + j, in));
    return _mm256_add_pd(_mm256_maskload_pd(L->prev + j, in), _mm256_sub_pd(q, _mm256_div_pd(_mm256_mul_pd(ss, ss), ws)));
}

static inline __m256d min4(__m256d v) /* the least of four in every lane */
{
    v = _mm256_min_pd(v, _mm256_permute2f128_pd(v, v, 1));
    return _mm256_min_pd(v, _mm256_permute_pd(v, 5));
}

static inline int64_t argmin(layer_t *L, int64_t m, int64_t lo, int64_t hi, double *best)
{
    const __m256d vw = _mm256_set1_pd(L->W[m]), vs = _mm256_set1_pd(L->S[m]), vq = _mm256_set1_pd(L->Q[m]);
    const __m256d inf = _mm256_set1_pd(INFINITY), sign = _mm256_set1_pd(-0.0);
    const __m256i lane = _mm256_set_epi64x(3, 2, 1, 0);
#define FINITE(v) _mm256_cmp_pd(_mm256_andnot_pd(sign, v), inf, _CMP_LT_OQ)
    if (hi - lo < 4) { /* one masked vector: lane order is index order */
        const __m256i in = _mm256_cmpgt_epi64(_mm256_set1_epi64x(hi + 1 - lo), lane);
        const __m256d v = _mm256_blendv_pd(inf, values(L, vw, vs, vq, in, lo), _mm256_castsi256_pd(in));
        L->bad |= _mm256_movemask_pd(_mm256_or_pd(FINITE(v), _mm256_castsi256_pd(_mm256_xor_si256(in, _mm256_set1_epi64x(-1))))) != 0xF;
        const __m256d b = min4(v);
        *best = _mm256_cvtsd_f64(b);
        return lo + __builtin_ctz((unsigned)_mm256_movemask_pd(_mm256_cmp_pd(v, b, _CMP_EQ_OQ)) | 0x10u);
    }
    __m256d vb = inf, fin = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    __m256i vi = _mm256_set1_epi64x(INT64_MAX), idx = _mm256_add_epi64(_mm256_set1_epi64x(lo), lane);
    const __m256i all = _mm256_set1_epi64x(-1), four = _mm256_set1_epi64x(4);
    int64_t j = lo;
    for (; j + 4 <= hi + 1; j += 4, idx = _mm256_add_epi64(idx, four)) {
        const __m256d v = values(L, vw, vs, vq, all, j);
        fin = _mm256_and_pd(fin, FINITE(v));
        const __m256d lt = _mm256_cmp_pd(v, vb, _CMP_LT_OQ); /* strictly: each lane keeps its leftmost */
        vb = _mm256_blendv_pd(vb, v, lt);
        vi = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(vi), _mm256_castsi256_pd(idx), lt));
    }
    if (j <= hi) { /* the rest: one masked vector */
        const __m256i in = _mm256_cmpgt_epi64(_mm256_set1_epi64x(hi + 1 - j), lane);
        const __m256d v = values(L, vw, vs, vq, in, j);
        fin = _mm256_and_pd(fin, _mm256_or_pd(FINITE(v), _mm256_castsi256_pd(_mm256_xor_si256(in, all))));
        const __m256d lt = _mm256_and_pd(_mm256_cmp_pd(v, vb, _CMP_LT_OQ), _mm256_castsi256_pd(in));
        vb = _mm256_blendv_pd(vb, v, lt);
        vi = _mm256_castpd_si256(_mm256_blendv_pd(_mm256_castsi256_pd(vi), _mm256_castsi256_pd(idx), lt));
    }
#undef FINITE
    L->bad |= _mm256_movemask_pd(fin) != 0xF;
    const __m256d b = min4(vb);
    *best = _mm256_cvtsd_f64(b);
    int64_t li[4], at = INT64_MAX; /* the least index among the lanes holding the least value */
    _mm256_storeu_si256((__m256i *)li, vi);
    const int eq = _mm256_movemask_pd(_mm256_cmp_pd(vb, b, _CMP_EQ_OQ));
    for (int l = 0; l < 4; l++)
        if (eq >> l & 1 && li[l] < at) at = li[l];
    return at;
}
#endif

/* The task's middle i: its D and minimiser; returns the minimiser. */
static inline int64_t solve(layer_t *L, task c, int64_t *mid)
{
    *mid = c.ilo + (c.ihi - c.ilo) / 2;
    const int64_t hi = c.jhi < *mid - 1 ? c.jhi : *mid - 1;
    const int64_t opt = argmin(L, *mid, c.jlo, hi, &L->D[*mid]);
    L->arg[*mid] = opt;
    return opt;
}

/* A task of at most LEAF i's, breadth first. */
static void subtree(layer_t *L, task first)
{
    task *cur = L->buf, *next = L->buf + LEAF;
    int64_t nc = 1;
    cur[0] = first;
    while (nc) {
        int64_t nn = 0;
        for (int64_t t = 0; t < nc; t++) {
            const task c = cur[t];
            int64_t mid;
            const int64_t opt = solve(L, c, &mid);
            if (mid - 1 >= c.ilo) next[nn++] = (task){c.ilo, mid - 1, c.jlo, opt};
            if (mid + 1 <= c.ihi) next[nn++] = (task){mid + 1, c.ihi, opt, c.jhi};
        }
        task *t = cur;
        cur = next;
        next = t;
        nc = nn;
    }
}

/* A task, depth first down to subtrees of LEAF i's (left halves by recursion, depth <= log2 d; right by loop). */
static void tree(layer_t *L, task c)
{
    while (c.ilo <= c.ihi) {
        if (c.ihi - c.ilo + 1 <= LEAF) {
            subtree(L, c);
            return;
        }
        int64_t mid;
        const int64_t opt = solve(L, c, &mid);
        tree(L, (task){c.ilo, mid - 1, c.jlo, opt});
        c = (task){mid + 1, c.ihi, opt, c.jhi};
    }
}

/* Words (8 bytes) of the work array selpres_kmeans1d needs for d distinct values and G groups. */
int64_t selpres_kmeans1d_work(int64_t d, int64_t G)
{
    return (G + 4) * (d + 1) + 8 * (int64_t)LEAF;
}

/* The layers 2..G of x[d] (sorted distinct, centred) and w[d] (multiplicities), 2 <= G <= d, in work (at least
   selpres_kmeans1d_work(d, G) words): W, S, Q at words 0, d + 1, 2 (d + 1); layer k's minimisers at 5 (d + 1) +
   (k - 2)(d + 1); the last layer in full if `full` (its D then at 3 (d + 1)), else its D_G(d) and minimiser only.
   Returns 0 or -2 (a candidate not finite). */
static int layers(const double *x, const double *w, int64_t d, int64_t G, double *work, int full)
{
    const int64_t n1 = d + 1;
    double *W = work, *S = work + n1, *Q = work + 2 * n1, *prev = work + 3 * n1, *D = work + 4 * n1;
    int64_t *args = (int64_t *)(work + 5 * n1);
    task *buf = (task *)(work + (G + 4) * n1);
    W[0] = S[0] = Q[0] = 0.0;
    for (int64_t i = 0; i < d; i++) { /* as numpy: cumsum of w, of w * x and of (w * x) * x */
        const double wx = w[i] * x[i];
        W[i + 1] = W[i] + w[i];
        S[i + 1] = S[i] + wx;
        Q[i + 1] = Q[i] + wx * x[i];
    }
    prev[0] = INFINITY;
    for (int64_t i = 1; i <= d; i++) prev[i] = Q[i] - S[i] * S[i] / W[i]; /* one group: the SSE of 0..i-1 */
    for (int64_t k = 2; k <= G; k++) {
        layer_t L = {W, S, Q, prev, D, args + (k - 2) * n1, buf, 0};
        if (k < G || full) {
            tree(&L, (task){k, d, k - 1, d - 1});
            prev = D; /* D_k is the next layer's prev; its D takes the old prev's place */
            D = (double *)L.prev;
        } else { /* D_G(d) only: the chain of right halves from the whole range [G, d] to d */
            for (task c = {k, d, k - 1, d - 1};;) {
                int64_t mid;
                const int64_t opt = solve(&L, c, &mid);
                if (mid == d || L.bad) break;
                c = (task){mid + 1, d, opt, d - 1};
            }
        }
        if (L.bad) return -2;
    }
    if (full && prev != work + 3 * n1)
        for (int64_t i = 0; i <= d; i++) work[3 * n1 + i] = prev[i];
    return 0;
}

/* x[d]: sorted distinct values (centred), w[d]: their multiplicities; 1 <= G <= d groups; work: at least
   selpres_kmeans1d_work(d, G) words. Writes starts[G], each group's first index into x (starts[0] = 0).
   Returns 0, -2 (a candidate not finite: numpy decides) or -3 (G out of range). */
int selpres_kmeans1d(const double *x, const double *w, int64_t d, int64_t G, int64_t *starts, double *work)
{
    if (G < 1 || G > d) return -3;
    starts[0] = 0;
    if (G == 1) return 0;
    const int rc = layers(x, w, d, G, work, 0);
    if (rc) return rc;
    const int64_t *args = (const int64_t *)(work + 5 * (d + 1));
    int64_t end = d;
    for (int64_t k = G; k >= 2; k--) { /* backtrack: group k starts at its layer's minimiser for the end */
        end = args[(k - 2) * (d + 1) + end];
        starts[k - 1] = end;
    }
    return 0;
}

/* For the tests: every layer in full, left in work as `layers` describes (2 <= G <= d). */
int selpres_kmeans1d_layers(const double *x, const double *w, int64_t d, int64_t G, double *work)
{
    return G < 2 || G > d ? -3 : layers(x, w, d, G, work, 1);
}
