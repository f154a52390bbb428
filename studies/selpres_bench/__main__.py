from selpres_bench.main import main

raise SystemExit(main())
