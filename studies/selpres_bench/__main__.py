from selpres.bench.main import main

raise SystemExit(main())
