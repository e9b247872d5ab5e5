from vlmrl_cli.cli.entry import main

main()
