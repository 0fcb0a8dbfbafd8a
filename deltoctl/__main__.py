from deltoctl.cli.main import main

main()
