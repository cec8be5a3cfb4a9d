from sherpa_cli.cli.entry import main

main()
