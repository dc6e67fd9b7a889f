from trajectotree.cli import console

console()
