"""The settings layer every scenario's settings go through: TOML and --set parsing, conversion, range rules, error wording."""
