/* exp4 and sigmoid4: the AVX2 exp and logistic sigmoid of 4 float64 lanes, shared by sgd.c (online SGD)
 * and minibatch.c (mini-batch training), so both kernels compute the sigmoid with the same operations.
 * Needs <immintrin.h> and AVX2/FMA (the includer checks). */
#ifndef SELPRES_EXP4_H
#define SELPRES_EXP4_H

/* exp(x) for 4 doubles, |rel err| ~1e-16 (Cody-Waite reduction + degree-13 Taylor); x clamped to
   [-708, 708] (NaN passes through). Only used inside the sigmoid, where the clamp is invisible. */
static inline __m256d exp4(__m256d x) {
    x = _mm256_min_pd(_mm256_set1_pd(708.0), x);   /* operand order keeps NaN */
    x = _mm256_max_pd(_mm256_set1_pd(-708.0), x);
    __m256d n = _mm256_round_pd(_mm256_mul_pd(x, _mm256_set1_pd(1.4426950408889634)),
                                _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
    __m256d r = _mm256_fnmadd_pd(n, _mm256_set1_pd(6.93147180369123816490e-01), x);
    r = _mm256_fnmadd_pd(n, _mm256_set1_pd(1.90821492927058770002e-10), r);
    __m256d p = _mm256_set1_pd(1.0 / 6227020800.0);
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 479001600.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 39916800.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 3628800.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 362880.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 40320.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 5040.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 720.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 120.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 24.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0 / 6.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(0.5));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0));
    p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(1.0));
    __m256d t = _mm256_add_pd(n, _mm256_set1_pd(6755399441055744.0));   /* 1.5 * 2^52: n in the low bits */
    __m256i e = _mm256_slli_epi64(_mm256_add_epi64(_mm256_castpd_si256(t), _mm256_set1_epi64x(1023)), 52);
    return _mm256_mul_pd(p, _mm256_castsi256_pd(e));
}

static inline __m256d sigmoid4(__m256d z) {
    const __m256d one = _mm256_set1_pd(1.0);
    return _mm256_div_pd(one, _mm256_add_pd(one, exp4(_mm256_xor_pd(z, _mm256_set1_pd(-0.0)))));
}

#endif
