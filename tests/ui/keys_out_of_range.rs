// More keys than a data store can name (a key is a u8): refused at the macro's call, naming it.
psmpa_core::include_mission!(mod m = "../../../../missions/fetch-tea.json", keys = 18446744073709551615);

fn main() {}
