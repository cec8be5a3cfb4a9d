from sherpa_cli.cli.app import main

main()
