//! The link and the task loop against a scripted fake board (one test
//! binary: each binary links the whole runtime again).

mod fake_board;
mod link;
mod task_loop;
