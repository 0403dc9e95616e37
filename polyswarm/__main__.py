from polyswarm.cli import main

main()
