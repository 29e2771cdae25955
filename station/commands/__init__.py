"""One module per `station` subcommand; each defines `register(subparsers)`."""
