//! Unit tests of `link` (a file of their own: the link is long enough).

use super::*;
use crate::protocol::encode_reply;

const ADDRESS: u8 = 0x80;

/// A line whose board answers when the test says: `deliveries[k]` is
/// what arrives as the `k`-th request (from 1) is written. With
/// `hold`, bytes are seen only by a read that does not wait (the
/// driver was not running while they arrived).
#[derive(Default)]
struct Scripted {
    pending: Vec<u8>,
    deliveries: Vec<(usize, Vec<u8>)>,
    writes: usize,
    hold: bool,
}

impl Transport for Scripted {
    fn write_all(&mut self, _bytes: &[u8]) -> io::Result<()> {
        self.writes += 1;
        for (k, bytes) in &self.deliveries {
            if *k == self.writes {
                self.pending.extend_from_slice(bytes);
            }
        }
        Ok(())
    }

    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        if self.pending.is_empty() || (self.hold && !timeout.is_zero()) {
            std::thread::sleep(timeout);
            return Ok(0);
        }
        let n = self.pending.len().min(buf.len());
        buf[..n].copy_from_slice(&self.pending[..n]);
        self.pending.drain(..n);
        Ok(n)
    }

    fn clear_input(&mut self) -> io::Result<usize> {
        let n = self.pending.len();
        self.pending.clear();
        Ok(n)
    }
}

fn answer(command: Command, reply: Reply) -> Vec<u8> {
    encode_reply(ADDRESS, command, &reply).as_bytes().to_vec()
}

fn encoder(count: i32) -> Vec<u8> {
    answer(Command::ReadEncoderM2, Reply::Encoder { count, status: 0 })
}

fn board(line: Scripted, retries: u32) -> Board<Scripted> {
    Board::new(
        line,
        LinkSettings {
            address: ADDRESS,
            baud: 115_200,
            answer_timeout: Duration::from_millis(2),
            retries,
        },
    )
}

#[test]
fn a_late_answer_is_not_read_as_the_next_requests_answer() {
    // Request 1 (an encoder read) is answered only as request 2 (a
    // speed) goes out: its answer, beginning with 0xff like an
    // acknowledgement, and then the acknowledgement.
    let mut late = encoder(-5);
    late.push(0xff);
    let line = Scripted {
        deliveries: vec![(2, late), (3, encoder(1234))],
        ..Scripted::default()
    };
    let mut b = board(line, 0);
    assert!(matches!(
        b.read_encoder(Motor::M2),
        Err(LinkError::NoAnswer { .. })
    ));
    assert_eq!(b.set_speed(Motor::M2, 100), Ok(()));
    assert_eq!(b.read_encoder(Motor::M2), Ok((1234, 0)));
    let h = b.health();
    assert_eq!(
        (h.late_answers, h.crc_errors, h.bad_answers, h.stray_bytes),
        (1, 0, 0, 0),
        "{h}"
    );
}

#[test]
fn a_retry_reads_the_late_answer_then_its_own_and_the_next_read_is_fresh() {
    // The first attempt's answer (100) comes during the retry, the
    // retry's own (200) right after; the next transaction's is 300.
    let mut both = encoder(100);
    both.extend(encoder(200));
    let line = Scripted {
        deliveries: vec![(2, both), (3, encoder(300))],
        ..Scripted::default()
    };
    let mut b = board(line, 1);
    assert_eq!(b.read_encoder(Motor::M2), Ok((200, 0)));
    assert_eq!(b.read_encoder(Motor::M2), Ok((300, 0)));
    assert_eq!(b.health().late_answers, 1);
    assert_eq!(b.health().crc_errors, 0);
}

#[test]
fn an_owed_answer_never_sent_is_skipped() {
    // Request 1 is dropped by the board; request 2's answer is the only one.
    let line = Scripted {
        deliveries: vec![(2, answer(Command::ReadStatus, Reply::Status(7)))],
        ..Scripted::default()
    };
    let mut b = board(line, 0);
    assert!(b.read_encoder(Motor::M2).is_err());
    assert_eq!(b.read_status(), Ok(7));
    assert_eq!(b.health().owed_skipped, 1);
    assert_eq!(b.health().late_answers, 0);
    // The same command dropped, then answered: its one answer is the retry's.
    let line = Scripted {
        deliveries: vec![(2, encoder(42))],
        ..Scripted::default()
    };
    let mut b = board(line, 1);
    assert_eq!(b.read_encoder(Motor::M2), Ok((42, 0)));
}

#[test]
fn an_owed_answer_still_missing_at_the_deadline_stays_owed() {
    // The line stalls over two transactions; then everything arrives.
    let mut burst = encoder(5);
    burst.push(0xff);
    burst.extend(answer(Command::ReadStatus, Reply::Status(9)));
    let line = Scripted {
        deliveries: vec![(3, burst)],
        ..Scripted::default()
    };
    let mut b = board(line, 0);
    assert!(b.read_encoder(Motor::M2).is_err());
    assert!(b.set_speed(Motor::M2, 1).is_err());
    assert_eq!(b.read_status(), Ok(9));
    let h = b.health();
    assert_eq!(
        (h.late_answers, h.crc_errors, h.bad_answers),
        (2, 0, 0),
        "{h}"
    );
}

#[test]
fn an_answer_that_arrived_while_the_driver_was_not_running_is_found() {
    let line = Scripted {
        deliveries: vec![(1, encoder(77))],
        hold: true,
        ..Scripted::default()
    };
    let mut b = board(line, 0);
    assert_eq!(b.read_encoder(Motor::M2), Ok((77, 0)));
    assert_eq!(b.health().no_answer, 0);
}

#[test]
fn the_attempt_time_is_both_frames_on_the_wire_plus_the_turnaround() {
    let b = board(Scripted::default(), 0);
    // A speed request (7 bytes) and its acknowledgement: 80 bits at
    // 115200 baud is 694 us.
    let t = b.attempt_time(Command::SpeedM2, 7);
    assert_eq!(t, Duration::from_micros(694) + Duration::from_millis(2));
}
