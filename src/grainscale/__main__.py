from grainscale.cli import main

raise SystemExit(main())
