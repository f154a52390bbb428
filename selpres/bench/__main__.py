from selpres.bench.bench import main

main()
