"""The benchmarks of selpres: ``selpres-bench``, ``python -m selpres_bench.scale``, ``python -m selpres_bench.pruning``
and the other sections' modules, every ratio measured side by side in one run.

Apart from the library (the repository's ``studies/`` distribution, installed beside selpres by ``make setup``), not
in its wheel. It times the library's insides (an engine's epoch, the kernels, the Sampler's shuffles, whole jobs), so
unlike the studies it may import any module of selpres, as the tests do; nothing in selpres imports it.
"""
