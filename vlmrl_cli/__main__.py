from vlmrl_cli.cli.app import main

main()
